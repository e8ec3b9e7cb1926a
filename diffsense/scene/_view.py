"""A scene for people: a bird's-eye figure and a plain JSON form (used by the viewer CLI)."""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Polygon

from diffsense.scene._datatypes import KIND_NAMES, ROLE_NAMES, Scene
from diffsense.scene._road import Road, frenet_to_cartesian

ROLE_COLOURS = ("tab:blue", "tab:red", "tab:green", "tab:orange", "tab:purple", "0.6")
_SNAPSHOT_S = 2.0  # body outlines drawn every 2 s


def road_json(road: Road, name: str) -> dict[str, Any]:
    """The road's geometry as plain numbers (its pieces, zero-length padding left out)."""
    pieces = [k for k in range(len(road.start_s_m)) if k == 0 or road.start_s_m[k] < road.length_m]
    return {
        "name": name, "length_m": float(road.length_m), "lane_width_m": float(road.lane_width_m),
        "num_lanes": int(road.num_lanes), "auxiliary_lanes": int(road.auxiliary_lanes),
        "segments": [
            {"start_s_m": float(s), "curvature_1pm": float(k), "x_m": float(x), "y_m": float(y), "heading_rad": float(h)}
            for s, k, x, y, h in zip(*(np.asarray(a)[pieces] for a in (
                road.start_s_m, road.curvature_1pm, road.start_x_m, road.start_y_m, road.start_heading_rad)))
        ],
    }


def scene_json(scene: Scene, road: Road, road_name: str) -> dict[str, Any]:
    """One scene [T, V] as JSON-ready data: road, and per present vehicle its size and track."""
    mm = lambda a: np.round(np.asarray(a, np.float64), 3).tolist()  # noqa: E731
    vehicles = []
    for v in range(scene.num_vehicles):
        if not bool(scene.present[v]):
            continue
        vehicles.append({
            "role": ROLE_NAMES[int(scene.role[v])], "kind": KIND_NAMES[int(scene.kind[v])],
            "length_m": round(float(scene.length_m[v]), 3), "width_m": round(float(scene.width_m[v]), 3),
            "s_m": mm(scene.s_m[:, v]), "d_m": mm(scene.d_m[:, v]),
            "x_m": mm(scene.x_m[:, v]), "y_m": mm(scene.y_m[:, v]),
        })
    return {"dt_s": scene.dt_s, "num_frames": scene.num_frames, "road": road_json(road, road_name), "vehicles": vehicles}


def _outline(x, y, heading, length, width):
    c, s = np.cos(heading), np.sin(heading)
    corners = np.array([[0.5, 0.5], [0.5, -0.5], [-0.5, -0.5], [-0.5, 0.5]]) * [length, width]
    return np.stack([x + c * corners[:, 0] - s * corners[:, 1], y + s * corners[:, 0] + c * corners[:, 1]], -1)


def _draw_road(ax, road: Road, s_lo: float, s_hi: float, world: bool) -> None:
    s = np.linspace(s_lo, s_hi, 400)
    lanes, width = int(road.num_lanes), float(road.lane_width_m)
    for k in range(lanes + 1):
        d = np.full_like(s, k * width)
        edge = k in (0, lanes)
        style = dict(color="k", lw=1.2 if edge else 0.6, ls="-" if edge else (0, (6, 6)))
        if world:
            x, y, _ = (np.asarray(a) for a in frenet_to_cartesian(road, s, d))
            ax.plot(x, y, **style)
        else:
            ax.plot(s, d, **style)


def scene_figure(scene: Scene, road: Road, title: str = "") -> Figure:
    """Bird's-eye view (world x, y, true scale) above the road frame (s, d, lateral stretched)."""
    fig = Figure(figsize=(14, 7.5), constrained_layout=True)
    top, bottom = fig.subplots(2, 1)
    present = np.asarray(scene.present)
    s_all = np.asarray(scene.s_m)[:, present]
    s_lo, s_hi = min(0.0, s_all.min() - 10.0), max(float(road.length_m), s_all.max() + 10.0)
    _draw_road(top, road, s_lo, s_hi, world=True)
    _draw_road(bottom, road, s_lo, s_hi, world=False)
    step = max(1, round(_SNAPSHOT_S / scene.dt_s))
    seen = set()
    for v in np.flatnonzero(present):
        role = int(scene.role[v])
        colour = ROLE_COLOURS[role]
        label = ROLE_NAMES[role] if role not in seen else None
        seen.add(role)
        x, y, h = (np.asarray(a[:, v]) for a in (scene.x_m, scene.y_m, scene.heading_rad))
        s, d = np.asarray(scene.s_m[:, v]), np.asarray(scene.d_m[:, v])
        top.plot(x, y, color=colour, lw=1.5, label=label)
        bottom.plot(s, d, color=colour, lw=1.5, label=label)
        length, width = float(scene.length_m[v]), float(scene.width_m[v])
        for k in range(0, scene.num_frames, step):
            alpha = 0.25 + 0.6 * k / max(scene.num_frames - 1, 1)
            top.add_patch(Polygon(_outline(x[k], y[k], h[k], length, width), color=colour, alpha=alpha, lw=0))
            bottom.add_patch(Polygon(_outline(s[k], d[k], 0.0, length, width), color=colour, alpha=alpha, lw=0))
    top.set_aspect("equal")
    top.set(xlabel="x [m]", ylabel="y [m]", title=title or "scene (bird's-eye view)")
    bottom.set(xlabel="s along the road [m]", ylabel="d to the left [m]",
               title=f"road frame (lateral stretched); outlines every {_SNAPSHOT_S:g} s, darker = later")
    bottom.legend(loc="upper right", ncol=6, fontsize=8)
    return fig
