"""The relevant set: what can reach the target's grid or hide it stays, far traffic goes."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.config import replace
from diffsense.scene import (
    BACKGROUND,
    EGO,
    TARGET,
    Scene,
    load_road,
    load_scenario,
    relevant_mask,
    relevant_vehicles,
    simulate_scenario,
)
from diffsense.scene._road import frenet_to_cartesian

# The CS-LSTM's 3 s history and 13 cells of 15 ft (+-97.5 ft = 29.718 m); the radar 4.2 m ahead.
REACH = dict(history_s=3.0, grid_half_length_m=29.718, sensor_reach_m=4.2)


@pytest.fixture(scope="module")
def sc01_with_background():
    cfg = load_scenario("sc01")
    plain = simulate_scenario(cfg, 24, jax.random.key(7))  # test_scene.py's shapes: compiled once
    crowded = simulate_scenario(replace(cfg, background={"count": 100}), 8, jax.random.key(7))
    # A variant does not depend on how many are drawn: the first 8 of `plain` are `crowded`'s.
    return jax.tree.map(lambda a: a[:8], plain), crowded


def test_far_background_costs_nothing(sc01_with_background):
    plain, crowded = sc01_with_background
    assert crowded.num_vehicles == 105
    kept_plain, kept_crowded = relevant_vehicles(plain, **REACH), relevant_vehicles(crowded, **REACH)
    assert kept_crowded.num_vehicles == kept_plain.num_vehicles <= 5  # padded to the batch's own max
    for field in dataclasses.fields(Scene):
        a, b = np.asarray(getattr(kept_plain, field.name)), np.asarray(getattr(kept_crowded, field.name))
        if field.name in ("x_m", "y_m", "heading_rad", "road_angle_rad"):
            # The same (s, d) mapped by two compiled programs: float32 may differ in the last bit.
            assert np.allclose(a, b, rtol=0.0, atol=1e-4)
        else:
            assert np.array_equal(a, b)  # the very same vehicles, untouched
    assert np.all(np.asarray(kept_crowded.role[:, :2]) == [EGO, TARGET])


def test_background_changes_lanes_by_mobil_without_collisions(sc01_with_background):
    _, crowded = sc01_with_background
    s, d = np.asarray(crowded.s_m, np.float64), np.asarray(crowded.d_m, np.float64)
    length, width = np.asarray(crowded.length_m)[:, None], np.asarray(crowded.width_m)[:, None]
    lateral = np.abs(d[..., :, None] - d[..., None, :]) < 0.5 * (width[..., :, None] + width[..., None, :])
    gap = np.abs(s[..., :, None] - s[..., None, :]) - 0.5 * (length[..., :, None] + length[..., None, :])
    gap = np.where(lateral & ~np.eye(s.shape[-1], dtype=bool), gap, np.inf)
    assert gap.min() > 0.0  # no two of the 105 vehicles ever touch
    bg = d[:, :, 5:]
    assert np.any(bg[:, -1] != bg[:, 0])  # MOBIL did change lanes (speeds differ by up to 20 km/h)
    # Between lane changes a vehicle is on a lane centre: changes are whole lanes.
    resting = np.diff(bg, axis=1) == 0.0  # frame k to k + 1
    resting = np.concatenate([resting, resting[:, -1:]], axis=1)
    lanes = bg / 3.66 - 0.5
    assert np.allclose(lanes[resting], np.round(lanes[resting]), atol=1e-3)
    road = load_road("us101")
    assert np.all(bg - 0.9 >= 0.0) and np.all(bg + 0.9 <= road.width_m)  # on the road (car 1.8 m wide)


def _line_scene(s_d: list[tuple[float, float]], frames: int = 120) -> Scene:
    """A scene of vehicles cruising at 20 m/s from the given (s, d) on the straight road."""
    road = load_road("straight")
    v = len(s_d)
    s0 = jnp.array([p[0] for p in s_d])
    d = jnp.broadcast_to(jnp.array([p[1] for p in s_d]), (frames, v))
    s = s0[None, :] + 2.0 * jnp.arange(frames)[:, None]
    x, y, angle = frenet_to_cartesian(road, s, d)
    vec = lambda val, dtype=jnp.float64: jnp.full((v,), val, dtype)  # noqa: E731
    return Scene(
        s_m=s, d_m=d, x_m=x, y_m=y, heading_rad=angle, road_angle_rad=angle, speed_mps=jnp.full((frames, v), 20.0),
        lane=jnp.floor(d / road.lane_width_m).astype(jnp.int32), length_m=vec(4.6), width_m=vec(1.8),
        kind=vec(0, jnp.int32), role=jnp.array([EGO, TARGET] + [BACKGROUND] * (v - 2)), present=vec(True, bool),
    )


def test_occluders_between_ego_and_target_are_kept():
    lane1, lane2 = 1.5 * 3.66, 2.5 * 3.66
    scene = _line_scene([
        (0.0, lane1),      # ego
        (80.0, lane1),     # target, 80 m ahead
        (40.0, lane1),     # between them, 40 m from the target (outside its grid): an occluder
        (40.0, 10.5),      # beside the line of sight, lane 2: could still cut it (conservative)
        (-60.0, lane1),    # behind the ego: neither
        (180.0, lane2),    # 100 m beyond the target: neither
        (95.0, lane2),     # in the target's grid (left lane, +15 m)
    ])
    mask = np.asarray(jax.jit(lambda sc: relevant_mask(sc, **REACH))(scene))
    assert mask.tolist() == [True, True, True, True, False, False, True]
    kept = relevant_vehicles(scene, **REACH)
    assert kept.num_vehicles == 5 and np.array_equal(kept.s_m, scene.s_m[:, [0, 1, 2, 3, 6]])


def test_prediction_frames_limit_the_history_windows():
    # Vehicle 2 starts in the target's grid, 15 m behind it in the target's lane, then falls back
    # by 1.5 m per frame; the ego is 300 m ahead, so vehicle 2 is never between it and the target.
    scene = _line_scene([(360.0, 9.15), (60.0, 5.49), (45.0, 5.49)] + [(-400.0, 1.83)] * 4)
    s = scene.s_m.at[:, 2].set(45.0 + 0.5 * jnp.arange(120.0))
    scene = dataclasses.replace(scene, s_m=s)
    assert bool(relevant_mask(scene, jnp.array([10]), **REACH)[2])
    late = relevant_mask(scene, jnp.array([110]), **REACH)  # history 80..110: 100+ m behind the target
    assert not bool(late[2]) and bool(late[0]) and bool(late[1])
    assert np.array_equal(relevant_mask(scene, **REACH), [True, True, True] + [False] * 4)
