"""A scene for people: a bird's-eye figure and a plain JSON form (used by the viewer CLI)."""

from __future__ import annotations

from typing import Any

import jax
import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Polygon

from diffsense.scene._datatypes import EGO, KIND_NAMES, ROLE_NAMES, TARGET_INDEX, Scene
from diffsense.scene._road import Road, frenet_to_cartesian

ROLE_COLOURS = ("tab:blue", "tab:red", "tab:green", "tab:orange", "tab:purple", "0.6")
_ZOOM_HALF_S = 3.0  # the bird's-eye panel shows +-3 s around the lane change


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


def _host(scene: Scene) -> Scene:
    """The scene as numpy arrays: indexing them costs nothing (a jax array compiles each index)."""
    return jax.tree.map(np.asarray, scene)


def scene_json(scene: Scene, road: Road, road_name: str) -> dict[str, Any]:
    """One scene [T, V] as JSON-ready data: road, and per present vehicle its size and track."""
    scene = _host(scene)
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
    lanes, width = int(road.num_lanes), float(road.lane_width_m)
    s = np.broadcast_to(np.linspace(s_lo, s_hi, 400), (lanes + 1, 400))
    d = np.broadcast_to(np.arange(lanes + 1)[:, None] * width, s.shape)
    x, y = (np.asarray(a) for a in frenet_to_cartesian(road, s, d)[:2]) if world else (s, d)
    for k in range(lanes + 1):
        edge = k in (0, lanes)
        ax.plot(x[k], y[k], color="k", lw=1.2 if edge else 0.6, ls="-" if edge else (0, (6, 6)))


def _lane_change_frame(scene: Scene) -> int:
    """The frame where the target's lateral speed peaks (mid lane change; the middle if none)."""
    rate = np.abs(np.diff(np.asarray(scene.d_m[:, TARGET_INDEX])))
    return int(rate.argmax()) if rate.max() > 0 else scene.num_frames // 2


def scene_figure(scene: Scene, road: Road, title: str = "") -> Figure:
    """Top: bird's-eye view (world x, y, true scale) of the 6 s around the target's lane change.
    Bottom: the whole scene in the road frame (s, d), lateral stretched."""
    scene = _host(scene)
    fig = Figure(figsize=(14, 8), constrained_layout=True)
    top, bottom = fig.subplots(2, 1, height_ratios=(1.0, 1.2))
    present = np.flatnonzero(np.asarray(scene.present))
    s_all = np.asarray(scene.s_m)[:, present]
    s_lo, s_hi = min(0.0, s_all.min() - 10.0), max(float(road.length_m), s_all.max() + 10.0)
    mid = _lane_change_frame(scene)
    half = round(_ZOOM_HALF_S / scene.dt_s)
    zoom = slice(max(mid - half, 0), min(mid + half + 1, scene.num_frames))
    _draw_road(top, road, s_all[zoom].min() - 15.0, s_all[zoom].max() + 15.0, world=True)
    _draw_road(bottom, road, s_lo, s_hi, world=False)
    seen = set()
    for v in present:
        role = int(scene.role[v])
        style = dict(color=ROLE_COLOURS[role], lw=3.0 if role == EGO else 1.5,
                     label=ROLE_NAMES[role] if role not in seen else None)
        seen.add(role)
        x, y, h = (np.asarray(a[:, v]) for a in (scene.x_m, scene.y_m, scene.heading_rad))
        s, d = np.asarray(scene.s_m[:, v]), np.asarray(scene.d_m[:, v])
        top.plot(x[zoom], y[zoom], **style)
        bottom.plot(s, d, **style)
        size = float(scene.length_m[v]), float(scene.width_m[v])
        _outlines(top, x, y, h, size, range(zoom.start, zoom.stop, round(1.0 / scene.dt_s)), style["color"])
        _outlines(bottom, s, d, np.zeros_like(s), size, range(0, scene.num_frames, round(2.0 / scene.dt_s)), style["color"])
    t0, t1 = zoom.start * scene.dt_s, (zoom.stop - 1) * scene.dt_s
    top.set_aspect("equal", adjustable="datalim")
    top.set(xlabel="x [m]", ylabel="y [m]", title=f"{title or 'scene'}\nbird's-eye view, t = {t0:.1f} .. {t1:.1f} s "
            "around the lane change (outlines every 1 s, darker = later)")
    bottom.set(xlabel="s along the road [m]", ylabel="d to the left [m]",
               title="whole scene in the road frame (lateral stretched; outlines every 2 s)")
    bottom.legend(loc="upper right", ncol=6, fontsize=8)
    return fig


def _outlines(ax, x, y, heading, size, frames, colour) -> None:
    frames = list(frames)
    for n, k in enumerate(frames):
        alpha = 0.2 + 0.6 * n / max(len(frames) - 1, 1)
        ax.add_patch(Polygon(_outline(x[k], y[k], heading[k], *size), color=colour, alpha=alpha, lw=0))
