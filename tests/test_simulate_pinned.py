"""The scene simulation written out again as plain loops over frames and vehicles.

`_simulate.py`'s leader search, its steady-state IDM parameters and its frame update (IDM with a
braking floor, the ballistic step that stops at v = 0, the quintic lane change, MOBIL decisions
every few frames, the world pose and heading) are restated here in numpy, one vehicle pair at a
time, from their docstrings. The IDM acceleration, the quintic profile, MOBIL's choice and the
road's geometry are called from the library (each pinned by hand in its own test file).
Parameters differ from the shipped ones and from each other, so a swapped field changes a value.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.config import replace
from diffsense.runtime._errors import InputError
from diffsense.scene import load_scenario, simulate_scenario
from diffsense.scene._background_mobil import lane_change_starts
from diffsense.scene._datatypes import ADJACENT, BACKGROUND, CAR, EGO, LEAD, TARGET, TRUCK, VAN
from diffsense.scene._idm import FREE_ROAD_GAP_M, IDMParams, idm_acceleration
from diffsense.scene._lane_change import quintic_lateral_offset_m, quintic_lateral_speed_mps
from diffsense.scene._mobil import MOBILParams
from diffsense.scene._road import curvature_1pm, frenet_to_cartesian, lane_index, load_road
from diffsense.scene._scenario_config import DriverModel, load_vehicle_models
from diffsense.scene._simulate import MIN_DESIRED_SPEED_MPS, SCENE_DT_S, _idm, leaders, simulate_numbers, simulate_plan
from diffsense.scene._variants import VehiclePlan, scenario_numbers

DRIVER = DriverModel(time_headway_s=1.3, min_gap_m=2.5, max_accel_mps2=1.2, comfort_decel_mps2=1.7,
                     accel_exponent=3.5, max_brake_mps2=6.0, follower_speed_ratio=1.2,
                     min_time_headway_s=0.7, max_time_headway_s=2.2, lateral_margin_m=0.25)
ROAD = load_road("us101")  # 3.66 m lanes; a left curve of 1/1200 m from s = 120 to 280 m
W = 3.66
DT = 0.1


def ref_leaders(s, d, v, length, width, margin, heading_to=None, lane_width=0.0):
    """(gap [m], leader speed [m/s]) per vehicle: the nearest j ahead (at equal s, the higher
    index) whose widened body overlaps, or which heads into i's lane, or into whose lane i heads."""
    n = len(s)
    gap, lead_v = np.full(n, FREE_ROAD_GAP_M), np.array(v, dtype=float)
    for i in range(n):
        best, who = FREE_ROAD_GAP_M, None
        for j in range(n):
            ahead = s[j] - s[i]
            in_front = ahead > 0 or (ahead == 0 and j > i)
            same = abs(d[j] - d[i]) < 0.5 * (width[i] + width[j]) + 2.0 * margin
            if heading_to is not None:
                same = same or abs(heading_to[j] - d[i]) < 0.5 * lane_width
                same = same or abs(d[j] - heading_to[i]) < 0.5 * lane_width
            g = ahead - 0.5 * (length[i] + length[j])
            if in_front and same and g < best:
                best, who = g, j
        gap[i] = best
        if best < FREE_ROAD_GAP_M:
            lead_v[i] = v[who]
    return gap, lead_v


def ref_idm(plan, driver):
    """(desired speed [m/s], time headway [s]) per vehicle, from the start state."""
    p = {k: np.asarray(getattr(plan, k), float) for k in ("s_m", "d_from_m", "speed_mps", "length_m", "width_m")}
    gap, _ = ref_leaders(p["s_m"], p["d_from_m"], p["speed_mps"], p["length_m"], p["width_m"], driver.lateral_margin_m)
    v0, headway = [], []
    for g, speed in zip(gap, p["speed_mps"]):
        v = max(speed, MIN_DESIRED_SPEED_MPS)
        t = (g * math.sqrt(1.0 - driver.follower_speed_ratio ** -driver.accel_exponent) - driver.min_gap_m) / v
        if t <= driver.max_time_headway_s:
            v0.append(driver.follower_speed_ratio * v)
            headway.append(max(t, driver.min_time_headway_s))
        else:
            v0.append(v)
            headway.append(driver.time_headway_s)
    return np.array(v0), np.array(headway)


def _idm_params(v0, headway, driver):
    return IDMParams(desired_speed_mps=jnp.asarray(v0), time_headway_s=jnp.asarray(headway),
                     min_gap_m=driver.min_gap_m, max_accel_mps2=driver.max_accel_mps2,
                     comfort_decel_mps2=driver.comfort_decel_mps2, accel_exponent=driver.accel_exponent)


def ref_simulate(plan, road, driver, num_frames, mobil=None, period=10):
    """Frame by frame: (s, v, d, d_rate) [T, V] and the (x, y, heading, lane) of the scene."""
    f = lambda a: np.asarray(a, float).copy()  # noqa: E731
    s, v = f(plan.s_m), f(plan.speed_mps)
    lc_start, d_from, d_to, dur = f(plan.lc_start_s), f(plan.d_from_m), f(plan.d_to_m), f(plan.lc_duration_s)
    length, width = f(plan.length_m), f(plan.width_m)
    background = np.asarray(plan.role) == BACKGROUND
    idm = _idm_params(*ref_idm(plan, driver), driver)
    out = {k: [] for k in ("s", "v", "d", "d_rate")}
    for k in range(num_frames):
        t = k * DT
        d = np.array([float(quintic_lateral_offset_m(t, lc_start[i], dur[i], d_from[i], d_to[i])) for i in range(len(s))])
        rate = np.array([float(quintic_lateral_speed_mps(t, lc_start[i], dur[i], d_from[i], d_to[i])) for i in range(len(s))])
        announced = background & (t >= lc_start) & (t < lc_start + dur)
        gap, lead_v = ref_leaders(s, d, v, length, width, driver.lateral_margin_m, np.where(announced, d_to, d), W)
        a = np.maximum(np.asarray(idm_acceleration(jnp.asarray(v), jnp.asarray(gap), jnp.asarray(lead_v), idm)),
                       -driver.max_brake_mps2)
        if mobil is not None and k % period == 0:
            free = background & (t >= lc_start + dur)
            starts, to = lane_change_starts(*(jnp.asarray(x) for x in (s, d, d_to, v, a, length)), idm,
                                            jnp.asarray(free), jnp.asarray(W), jnp.asarray(road.num_lanes), mobil)
            starts, to = np.asarray(starts), np.asarray(to)
            lc_start = np.where(starts, t, lc_start)
            d_from = np.where(starts, d_to, d_from)
            d_to = np.where(starts, to, d_to)
        for name, value in (("s", s), ("v", v), ("d", d), ("d_rate", rate)):
            out[name].append(value.copy())
        v_next = v + a * DT
        step = np.where(v_next < 0.0, v**2 / (2.0 * np.where(v_next < 0.0, -a, 1.0)), 0.5 * (v + v_next) * DT)
        s, v = s + step, np.maximum(v_next, 0.0)
    out = {k: np.array(x) for k, x in out.items()}
    x, y, angle = (np.asarray(a) for a in frenet_to_cartesian(road, out["s"], out["d"]))
    along = out["v"] * (1.0 - np.asarray(curvature_1pm(road, out["s"])) * out["d"])
    still = (np.abs(along) + np.abs(out["d_rate"])) == 0.0
    heading = angle + np.arctan2(out["d_rate"], np.where(still, 1.0, along))
    return out, x, y, heading, np.asarray(lane_index(road, out["d"]))


def _plan(rows):
    """VehiclePlan from rows (s, v, lane from, lane to, lc start, lc duration, length, width, kind, role)."""
    a = np.array(rows, dtype=float).T
    centre = lambda lane: (lane + 0.5) * W  # noqa: E731
    return VehiclePlan(s_m=jnp.asarray(a[0]), speed_mps=jnp.asarray(a[1]), d_from_m=jnp.asarray(centre(a[2])),
                       d_to_m=jnp.asarray(centre(a[3])), lc_start_s=jnp.asarray(a[4]), lc_duration_s=jnp.asarray(a[5]),
                       length_m=jnp.asarray(a[6]), width_m=jnp.asarray(a[7]),
                       kind=jnp.asarray(a[8], jnp.int32), role=jnp.asarray(a[9], jnp.int32))


# On the curve: an ego behind a lead, a cut-in from the left, a background car closing on a truck
# stopped in the right lane (it brakes to a stop: the ballistic step's v = 0 branch; with MOBIL it
# also changes lanes), a free background car far ahead, and in lane 3 a background car behind a
# slower one.
PLAN = _plan([
    (130.0, 25.0, 1, 1, 0.0, 4.0, 4.6, 1.85, CAR, EGO),
    (168.0, 24.0, 1, 1, 0.0, 4.0, 4.4, 1.80, CAR, LEAD),
    (150.0, 26.5, 2, 1, 1.2, 3.5, 5.0, 2.00, VAN, TARGET),
    (205.0, 0.0, 0, 0, 0.0, 4.0, 12.0, 2.50, TRUCK, ADJACENT),
    (170.0, 20.0, 0, 0, 0.0, 4.0, 4.5, 1.90, CAR, BACKGROUND),
    (420.0, 27.0, 2, 2, 0.0, 4.0, 4.7, 1.80, CAR, BACKGROUND),
    (140.0, 29.0, 3, 3, 0.0, 4.0, 4.5, 1.80, CAR, BACKGROUND),
    (171.0, 21.0, 3, 3, 0.0, 4.0, 4.8, 1.90, CAR, BACKGROUND),
])
MOBIL = MOBILParams(politeness=0.15, threshold_mps2=0.1, safe_decel_mps2=3.5, keep_right_bias_mps2=0.05)


def test_leaders_are_the_nearest_overlapping_vehicles_ahead():
    rng = np.random.default_rng(3)
    for trial in range(40):
        n = 7
        s = np.round(rng.uniform(0.0, 60.0, n), 0)  # rounded: equal s happen (ties go to the higher index)
        d = rng.choice([1.83, 5.49, 9.15], n) + rng.uniform(-1.5, 1.5, n)
        v, length, width = rng.uniform(5.0, 30.0, n), rng.uniform(4.0, 12.0, n), rng.uniform(1.6, 2.6, n)
        heading_to = np.where(rng.uniform(size=n) < 0.4, rng.choice([1.83, 5.49, 9.15], n), d)
        margin = rng.uniform(0.0, 0.6)
        for kwargs in ({}, {"heading_to": heading_to, "lane_width": W}):
            want = ref_leaders(s, d, v, length, width, margin, **kwargs)
            jkw = {"heading_to_m": jnp.asarray(kwargs["heading_to"]), "lane_width_m": W} if kwargs else {}
            got = leaders(*(jnp.asarray(x) for x in (s, d, v, length, width)), margin, **jkw)
            np.testing.assert_allclose(np.asarray(got[0]), want[0], rtol=1e-12, err_msg=f"gap, trial {trial} {kwargs and 'heading'}")
            np.testing.assert_allclose(np.asarray(got[1]), want[1], rtol=1e-12, err_msg=f"speed, trial {trial}")


def test_a_tie_in_s_goes_to_the_higher_index_and_touching_bodies_overlap_only_inside_the_margin():
    s, v, length = np.array([50.0, 50.0, 70.0]), np.array([20.0, 22.0, 24.0]), np.full(3, 4.0)
    width = np.full(3, 2.0)
    # 0 and 1 side by side, 2.4 m apart: with a 0.25 m margin their bodies (2 m + 0.5 m) overlap.
    d = np.array([0.0, 2.4, 0.0])
    gap, lead_v = leaders(*(jnp.asarray(x) for x in (s, d, v, length, width)), 0.25)
    np.testing.assert_allclose(np.asarray(gap), [-4.0, 16.0, FREE_ROAD_GAP_M])  # 0 follows 1 at equal s
    np.testing.assert_allclose(np.asarray(lead_v), [22.0, 24.0, 24.0])
    # 2.5 m apart is exactly the widened overlap: not the same lane (strict <); 0 follows 2.
    gap, lead_v = leaders(*(jnp.asarray(x) for x in (s, np.array([0.0, 2.5, 0.0]), v, length, width)), 0.25)
    np.testing.assert_allclose(np.asarray(gap), [16.0, FREE_ROAD_GAP_M, FREE_ROAD_GAP_M])
    np.testing.assert_allclose(np.asarray(lead_v), [24.0, 22.0, 24.0])
    # Heading into a lane (3.5 m lanes: every number below is exact in binary): exactly half a
    # lane away is not into it (strict <), whether j heads into i's lane or i into j's.
    for shift, inside in ((1.75, False), (1.7499, True)):
        # j = 1, 20 m to the side, heads to `shift` m from i = 0's centre; 2 is 0's leader.
        gap, _ = leaders(*(jnp.asarray(x) for x in (s, np.array([0.0, 20.0, 0.0]), v, length, width)), 0.25,
                         heading_to_m=jnp.asarray([0.0, shift, 0.0]), lane_width_m=3.5)
        assert float(gap[0]) == (-4.0 if inside else 16.0), shift
        # i = 0 heads to `shift` m from j = 1's centre (20 m to the side); 2 is out of the way.
        gap, _ = leaders(*(jnp.asarray(x) for x in (s, np.array([0.0, 20.0, 10.0]), v, length, width)), 0.25,
                         heading_to_m=jnp.asarray([20.0 - shift, 20.0, 10.0]), lane_width_m=3.5)
        assert float(gap[0]) == (-4.0 if inside else FREE_ROAD_GAP_M), shift


def test_steady_state_idm_parameters():
    v0, headway = ref_idm(PLAN, DRIVER)
    got = _idm(PLAN, DRIVER)
    np.testing.assert_allclose(np.asarray(got.desired_speed_mps), v0, rtol=1e-13)
    np.testing.assert_allclose(np.asarray(got.time_headway_s), headway, rtol=1e-13)
    for name in ("min_gap_m", "max_accel_mps2", "comfort_decel_mps2", "accel_exponent"):
        assert float(getattr(got, name)) == getattr(DRIVER, name), name
    # The plan covers every branch: followers (ratio x v), a clipped headway, free vehicles, and
    # a vehicle at rest whose desired speed is the floor.
    follows = np.isclose(v0, DRIVER.follower_speed_ratio * np.maximum(np.asarray(PLAN.speed_mps), 1.0))
    assert follows.any() and (~follows).any()
    assert np.any(headway == DRIVER.min_time_headway_s) and np.any(headway == DRIVER.time_headway_s)
    assert v0[3] == DRIVER.follower_speed_ratio * MIN_DESIRED_SPEED_MPS or v0[3] == MIN_DESIRED_SPEED_MPS


@pytest.mark.parametrize(("with_mobil", "period"), [(False, 7), (True, 7), (True, None)])
def test_trajectories_frame_by_frame(with_mobil, period):
    frames = 60  # not 61: at 6.0 s car 4's change (from 4.0 s) is half done, on the lane boundary
    mobil = MOBIL if with_mobil else None
    want, x, y, heading, lane = ref_simulate(PLAN, ROAD, DRIVER, frames, mobil, period or 10)
    if period is None:  # the default: a decision every 10 frames
        scene = jax.jit(simulate_plan, static_argnums=(2, 3, 4))(PLAN, ROAD, DRIVER, frames, DT, mobil)
        # Car 4 becomes free to decide at 4.0 s (its plan's lane change of 4 s from t = 0 ends),
        # frame 40, a decision frame: it starts its change right there.
        assert want["d"][40, 4] == want["d"][0, 4] != want["d"][41, 4]
    else:
        scene = jax.jit(simulate_plan, static_argnums=(2, 3, 4, 6))(PLAN, ROAD, DRIVER, frames, DT, mobil, period)
    for name, got in (("s", scene.s_m), ("v", scene.speed_mps), ("d", scene.d_m)):
        np.testing.assert_allclose(np.asarray(got), want[name], rtol=1e-10, atol=1e-9, err_msg=name)
    np.testing.assert_allclose(np.asarray(scene.x_m), x, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(np.asarray(scene.y_m), y, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(np.asarray(scene.heading_rad), heading, rtol=1e-10, atol=1e-9)
    np.testing.assert_array_equal(np.asarray(scene.lane), lane)
    np.testing.assert_allclose(np.asarray(scene.road_angle_rad),
                               np.asarray(frenet_to_cartesian(ROAD, want["s"], want["d"])[2]), rtol=1e-12)
    for name in ("length_m", "width_m", "kind", "role"):
        np.testing.assert_array_equal(np.asarray(getattr(scene, name)), np.asarray(getattr(PLAN, name)), err_msg=name)
    assert np.asarray(scene.present).all() and scene.present.shape == (8,) and scene.dt_s == DT
    # What the scene exercises: a stop (v = 0 reached mid-run), the cut-in, and with MOBIL a
    # background change decided on a multiple of the period.
    assert want["v"][-1, 4] == 0.0 and want["v"][frames // 2, 4] > 0.0
    assert abs(want["d"][-1, 2] - 1.5 * W) < 1e-9
    moved = np.abs(want["d"][-1] - want["d"][0]) > 1.0
    assert moved[4] == with_mobil and not moved[[0, 1, 3, 5, 6, 7]].any()


@pytest.mark.parametrize(("edit", "message"), [
    ({"ego": {"lane": 3}, "target_lane": 4, "adjacent_lane": 2}, "sc05: ego.lane 3 is not a lane of road 'straight' (0..2)"),
    ({"ego": {"lane": 2}, "target_lane": 3, "adjacent_lane": 1}, "sc05: target_lane 3 is not a lane of road 'straight' (0..2)"),
    ({"adjacent_lane": 3}, "sc05: adjacent_lane 3 is not a lane of road 'straight' (0..2)"),
    ({"adjacent_lane": -1}, "sc05: adjacent_lane -1 is not a lane of road 'straight' (0..2)"),
])
def test_a_lane_off_the_road_is_named_in_the_error(edit, message):
    cfg = load_scenario("sc05")  # the straight road: lanes 0..2
    if "ego" in edit:
        edit = {**edit, "ego": {**dataclasses.asdict(cfg.ego), **edit["ego"]}}
    with pytest.raises(InputError) as error:
        simulate_scenario(replace(cfg, **edit), 2, jax.random.key(0))
    assert str(error.value) == message


def test_a_speed_offset_is_a_config_edit_of_the_ego_speed():
    """A number (a Python float, or a numpy scalar, which is one) moves the ego's start speed, and
    with it every start speed, as editing ego.speed_kmh does; the scene keeps its float type."""
    cfg, key = load_scenario("sc01"), jax.random.key(4)
    base = simulate_scenario(cfg, 3, key)
    ego = {**dataclasses.asdict(cfg.ego)}
    ego["speed_kmh"] = {k: v + 7.2 for k, v in ego["speed_kmh"].items()}
    edited = simulate_scenario(replace(cfg, ego=ego), 3, key)
    for offset in (7.2, np.float64(7.2)):
        moved = simulate_scenario(cfg, 3, key, speed_offset_kmh=offset)
        assert moved.speed_mps.dtype == moved.s_m.dtype == jnp.float32, type(offset)
        np.testing.assert_allclose(np.asarray(moved.speed_mps[:, 0]), np.asarray(base.speed_mps[:, 0]) + 2.0, rtol=1e-6)
        np.testing.assert_allclose(np.asarray(moved.speed_mps), np.asarray(edited.speed_mps), rtol=1e-5, atol=1e-4)
        np.testing.assert_allclose(np.asarray(moved.s_m), np.asarray(edited.s_m), rtol=1e-5, atol=1e-3)


@pytest.mark.parametrize(("decision_period_s", "period", "other"), [(0.1, 1, 2), (0.3, 3, 1)])
def test_background_traffic_changes_lanes_by_the_models_mobil_at_its_decision_period(decision_period_s, period, other):
    cfg = replace(load_scenario("sc05"), background={"count": 6, "spacing_m": 25.0})  # close enough to interact
    models = load_vehicle_models()
    models = dataclasses.replace(models, mobil=dataclasses.replace(
        models.mobil, politeness=0.05, threshold_mps2=0.05, keep_right_bias_mps2=0.0, decision_period_s=decision_period_s))
    key, n = jax.random.key(2), 2
    got = simulate_scenario(cfg, n, key, models=models, dtype=jnp.float64)
    road = load_road(cfg.road)
    nums = scenario_numbers(cfg, models, road, jnp.float64)
    frames = round(cfg.duration_s / SCENE_DT_S) + 1
    mobil = MOBILParams(politeness=jnp.asarray(0.05), threshold_mps2=jnp.asarray(0.05),
                        safe_decel_mps2=jnp.asarray(models.mobil.safe_decel_mps2), keep_right_bias_mps2=jnp.asarray(0.0))
    want = simulate_numbers(nums, road, models.driver, key, n, frames, mobil, period)  # decision_period_s / 0.1 s
    jax.tree.map(lambda a, b: np.testing.assert_array_equal(np.asarray(a), np.asarray(b)), got, want)
    background = np.asarray(got.role[0]) == BACKGROUND
    assert np.any(np.abs(np.diff(np.asarray(got.lane)[:, :, background], axis=1)) > 0)  # some change lanes
    elsewhen = simulate_numbers(nums, road, models.driver, key, n, frames, mobil, other)
    assert not np.array_equal(np.asarray(elsewhen.d_m), np.asarray(got.d_m))
    without = simulate_scenario(replace(cfg, background={"count": 6, "spacing_m": 25.0, "mobil": False}), n, key, models=models,
                                dtype=jnp.float64)
    kept = np.asarray(without.d_m[:, :, background])  # without MOBIL every background car keeps its lane
    np.testing.assert_array_equal(kept, np.broadcast_to(np.asarray(want.d_m[:, :1, background]), kept.shape))
