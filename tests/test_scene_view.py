"""The scene viewer on hand-built scenes: the road's pieces as plain numbers (an arc's end from its
radius), a scene's JSON (absent vehicles left out, millimetre rounding), and what the figure
draws where: bodies turned by their heading, the window around the lane change, lanes and tracks.
"""

from __future__ import annotations

import matplotlib.colors as mcolors
import numpy as np
import pytest

from diffsense import scene as sc

T, LANE_W = 101, 3.66
PEAK = 60  # the frame after which the target moves sideways fastest


def _scene(lane_change: bool = True, frames: int = T, peak: int = PEAK, s0_m: float = 0.0, speed: float = 1.0,
           dtype=np.float64) -> sc.Scene:
    """Ego, target, two background vehicles and one absent slot (the fourth of five): `frames` at
    10 Hz (10 s by default), positions from `s0_m` at `speed` times the base speeds; the target's
    lateral move is fastest between frames `peak` and `peak + 1`."""
    t = np.arange(frames) * 0.1
    s = s0_m + speed * np.stack([20.0 + 25.0 * t, 35.0 + 26.0 * t, 5.0 + 24.0 * t, np.zeros(frames),
                                 12.345649 / speed + 20.0 * t], -1)
    step = np.zeros(frames - 1)
    if lane_change:  # a lateral move over peak - 15 .. peak + 15
        ks = np.arange(max(peak - 15, 0), min(peak + 16, frames - 1))
        step[ks] = LANE_W * (1.0 - np.abs(ks - peak) / 16.0) / 16.0
    d_target = 1.5 * LANE_W + np.concatenate([[0.0], np.cumsum(step)])
    d = np.stack([np.full(frames, 1.5 * LANE_W), d_target, np.full(frames, 0.5 * LANE_W), np.zeros(frames),
                  np.full(frames, 2.5 * LANE_W)], -1)
    zeros = np.zeros((frames, 5))
    f = lambda a: np.asarray(a, dtype)
    return sc.Scene(
        s_m=f(s), d_m=f(d), x_m=f(s), y_m=f(d), heading_rad=f(zeros), road_angle_rad=f(zeros),
        speed_mps=f(zeros + 25.0), lane=(d // LANE_W).astype(np.int32),
        length_m=f([4.6, 4.60049, 12.0, 4.6, 5.5]), width_m=f([1.8, 1.80049, 2.5, 1.8, 2.0]),
        kind=np.array([sc.CAR, sc.CAR, sc.TRUCK, sc.CAR, sc.VAN]), role=np.array([sc.EGO, sc.TARGET, sc.BACKGROUND, sc.BACKGROUND, sc.BACKGROUND]),
        present=np.array([True, True, True, False, True]),
    )


def test_road_json_keeps_the_real_pieces_with_an_arcs_end_from_its_radius():
    data = sc.road_json(sc.load_road("us101"), "us101")
    assert (data["name"], data["length_m"], data["lane_width_m"], data["num_lanes"], data["auxiliary_lanes"]) == (
        "us101", 640.0, 3.66, 6, 1)
    segments = data["segments"]
    assert [seg["start_s_m"] for seg in segments] == [0.0, 120.0, 280.0, 360.0, 520.0]  # no padding at 640 m
    turn = 160.0 / 1200.0  # the left bend: 160 m of R = 1200 m
    want = {"start_s_m": 280.0, "curvature_1pm": 0.0, "x_m": 120.0 + 1200.0 * np.sin(turn),
            "y_m": 1200.0 * (1.0 - np.cos(turn)), "heading_rad": turn}
    assert segments[2] == pytest.approx(want, rel=1e-9, abs=1e-12)
    assert segments[1]["curvature_1pm"] == pytest.approx(1.0 / 1200.0, rel=1e-12)
    assert segments[3]["curvature_1pm"] == pytest.approx(-1.0 / 1500.0, rel=1e-12)
    # One piece, padded to the road's end: the first piece is kept whatever its start.
    assert sc.road_json(sc.load_road("straight"), "straight")["segments"] == [
        {"start_s_m": 0.0, "curvature_1pm": 0.0, "x_m": 0.0, "y_m": 0.0, "heading_rad": 0.0}]


def test_scene_json_lists_present_vehicles_in_millimetres():
    scene = _scene()
    data = sc.scene_json(scene, sc.load_road("straight"), "straight")
    assert (data["dt_s"], data["num_frames"], data["road"]["name"]) == (0.1, T, "straight")
    vehicles = data["vehicles"]
    assert [(v["role"], v["kind"]) for v in vehicles] == [
        ("ego", "car"), ("target", "car"), ("background", "truck"), ("background", "van")]
    assert [(v["length_m"], v["width_m"]) for v in vehicles] == [(4.6, 1.8), (4.6, 1.8), (12.0, 2.5), (5.5, 2.0)]
    assert vehicles[3]["s_m"][:2] == [12.346, 14.346]  # 12.345649 and 14.345649 m to the millimetre
    assert vehicles[1]["d_m"][-1] == round(float(scene.d_m[-1, 1]), 3)
    assert vehicles[1]["width_m"] == 1.8  # 1.80049 m
    for v in vehicles:
        assert len(v["s_m"]) == len(v["d_m"]) == len(v["x_m"]) == len(v["y_m"]) == T
    # A float32 scene (what the simulation gives) is written as the same decimal millimetres.
    assert sc.scene_json(_scene(dtype=np.float32), sc.load_road("straight"), "straight") == data


def _corners(x, y, heading, length, width):
    """Front left, front right, rear right, rear left of a body at (x, y) turned by `heading`."""
    c, s = np.cos(heading), np.sin(heading)
    local = [(0.5 * length, 0.5 * width), (0.5 * length, -0.5 * width), (-0.5 * length, -0.5 * width),
             (-0.5 * length, 0.5 * width)]
    return np.array([[x + c * a - s * b, y + s * a + c * b] for a, b in local])


def test_outlines_are_the_bodies_turned_by_their_heading_in_the_top_panel_and_along_the_road_below():
    import dataclasses

    scene = _scene()
    turned = dataclasses.replace(scene, heading_rad=scene.heading_rad + 0.5)
    top, bottom = sc.scene_figure(turned, sc.load_road("straight")).axes
    # the ego's first outline in the zoom (frame 30: x = 20 + 25 * 3 = 95 m), and over the scene (frame 0)
    np.testing.assert_allclose(top.patches[0].get_xy()[:4], _corners(95.0, 1.5 * LANE_W, 0.5, 4.6, 1.8), atol=1e-12)
    np.testing.assert_allclose(bottom.patches[0].get_xy()[:4], _corners(20.0, 1.5 * LANE_W, 0.0, 4.6, 1.8), atol=1e-12)
    np.testing.assert_allclose(_corners(10.0, 5.0, np.pi / 2, 4.0, 2.0), [[9.0, 7.0], [11.0, 7.0], [11.0, 3.0], [9.0, 3.0]],
                               atol=1e-12)  # facing +y: front at y = 7, left side at x = 9


def test_the_figure_zooms_on_the_lane_change_and_names_each_role_once():
    scene = _scene()
    fig = sc.scene_figure(scene, sc.load_road("straight"), "hand scene")
    top, bottom = fig.axes
    # +-3 s around frame 60: frames 30..90.
    assert top.get_title().startswith("hand scene\nbird's-eye view, t = 3.0 .. 9.0 s around the lane change")
    assert bottom.get_legend_handles_labels()[1] == ["ego", "target", "background"]
    # no lane change: the zoom is on the middle frame (50), +-3 s
    steady = sc.scene_figure(_scene(lane_change=False), sc.load_road("straight")).axes[0]
    assert steady.get_title().startswith("scene\nbird's-eye view, t = 2.0 .. 8.0 s")
    # Outlines every 1 s in the zoom (frames 30, 40, .., 90) and every 2 s over the scene (0, 20, .., 100),
    # for the four present vehicles.
    assert (len(top.patches), len(bottom.patches)) == (4 * 7, 4 * 6)
    ego, target = top.lines[4:6]  # after the road's 4 lines, in the vehicles' order
    assert mcolors.to_hex(target.get_color()) == mcolors.to_hex(sc.ROLE_COLOURS[sc.TARGET])
    assert mcolors.to_hex(ego.get_color()) == mcolors.to_hex(sc.ROLE_COLOURS[sc.EGO])
    np.testing.assert_allclose(ego.get_xdata(), scene.x_m[30:91, 0])
    # The road drawn 15 m beyond the zoom's vehicles (top), and over the scene (bottom) from 10 m
    # behind its rearmost vehicle (5 m) or 0 m to the road's end or 10 m past its foremost;
    # 3 lanes: 4 lines each.
    s_zoom = scene.s_m[30:91][:, [0, 1, 2, 4]]  # the present vehicles
    np.testing.assert_allclose(top.lines[0].get_xdata()[[0, -1]], [s_zoom.min() - 15.0, s_zoom.max() + 15.0])
    assert list(bottom.lines[0].get_xdata()[[0, -1]]) == [-5.0, 1000.0]


def test_the_road_frame_panel_reaches_past_vehicles_beyond_the_road():
    import dataclasses

    scene = _scene()
    far = dataclasses.replace(scene, s_m=scene.s_m + 900.0, x_m=scene.x_m + 900.0)  # foremost at 1195 m
    bottom = sc.scene_figure(far, sc.load_road("straight")).axes[1]
    assert list(bottom.lines[0].get_xdata()[[0, -1]]) == [0.0, 1205.0]


def test_the_figure_draws_roads_tracks_and_outlines_in_their_frames():
    """On the US-101's left bend (R = 1200 m from s = 120 m to 280 m, centre at x = 120 m,
    y = 1200 m): the top panel's lane lines are arcs of radius 1200 m - k x 3.66 m, the bottom
    panel's the straight lines d = k x 3.66 m; each track and outline in its panel's frame."""
    scene = _scene(frames=41, peak=20, s0_m=140.0, speed=0.5)
    fig = sc.scene_figure(scene, sc.load_road("us101"))
    top, bottom = fig.axes
    assert top.get_title().startswith("scene\nbird's-eye view, t = 0.0 .. 4.0 s")  # zoom from frame 0
    for k in range(7):
        x, y = top.lines[k].get_xdata(), top.lines[k].get_ydata()
        np.testing.assert_allclose(np.hypot(x - 120.0, y - 1200.0), 1200.0 - k * LANE_W, rtol=1e-9)
        np.testing.assert_allclose(bottom.lines[k].get_ydata(), k * LANE_W, rtol=1e-12)
    tracks = bottom.lines[7:]
    for line, v in zip(tracks, (0, 1, 2, 4), strict=True):
        np.testing.assert_allclose(line.get_xdata(), scene.s_m[:, v])
        np.testing.assert_allclose(line.get_ydata(), scene.d_m[:, v])
    role_of = [0, 1, 5, 5]
    for panel, per_vehicle in ((top, 5), (bottom, 3)):  # frames 0, 10, .., 40 and 0, 20, 40
        for n, patch in enumerate(panel.patches):
            want = mcolors.to_rgb(sc.ROLE_COLOURS[role_of[n // per_vehicle]])
            assert mcolors.to_rgb(patch.get_facecolor()) == pytest.approx(want)
