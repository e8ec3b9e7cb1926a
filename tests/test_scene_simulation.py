"""The scenario simulation (`simulate_plan`, `simulate_scenario`) written out again as plain loops
over frames and vehicles: the leader search, the steady-state IDM parameters of every vehicle and
the frame update (IDM with a braking floor, the ballistic step that stops at v = 0, the quintic
lane change, MOBIL decisions every few frames, the world pose and heading), restated in numpy
from their docstrings. The IDM acceleration, the quintic profile and the road's geometry are the
library's (each pinned by hand in its own file); leaders and MOBIL's decisions are the loops of
tests/test_background_mobil.py. Parameters differ from the shipped ones and from each other, so a
swapped field changes a value. Also: equilibrium, gradients, errors and the speed offset.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_background_mobil import ref_leaders, ref_starts

from diffsense import scene
from diffsense.config import replace
from diffsense.runtime import InputError

DRIVER = scene.DriverModel(time_headway_s=1.3, min_gap_m=2.5, max_accel_mps2=1.2, comfort_decel_mps2=1.7,
                     accel_exponent=3.5, max_brake_mps2=6.0, follower_speed_ratio=1.2,
                     min_time_headway_s=0.7, max_time_headway_s=2.2, lateral_margin_m=0.25)
ROAD = scene.load_road("us101")  # 3.66 m lanes; a left curve of 1/1200 m from s = 120 to 280 m
W = 3.66
DT = 0.1
MIN_DESIRED_SPEED_MPS = 1.0


def ref_idm(plan, driver):
    """(desired speed [m/s], time headway [s]) per vehicle, from the start state."""
    p = {k: np.asarray(getattr(plan, k), float) for k in ("s_m", "d_from_m", "speed_mps", "length_m", "width_m")}
    gap, _ = ref_leaders(p["s_m"], p["d_from_m"], p["speed_mps"], p["length_m"], p["width_m"], driver.lateral_margin_m)
    v0, headway = [], []
    for g, speed in zip(gap, p["speed_mps"]):
        v = max(speed, MIN_DESIRED_SPEED_MPS)  # a floor: a vehicle at rest is well defined
        t = (g * math.sqrt(1.0 - driver.follower_speed_ratio ** -driver.accel_exponent) - driver.min_gap_m) / v
        if t <= driver.max_time_headway_s:
            v0.append(driver.follower_speed_ratio * v)
            headway.append(max(t, driver.min_time_headway_s))
        else:
            v0.append(v)
            headway.append(driver.time_headway_s)
    return np.array(v0), np.array(headway)


def _idm_params(v0, headway, driver):
    return scene.IDMParams(desired_speed_mps=jnp.asarray(v0), time_headway_s=jnp.asarray(headway),
                     min_gap_m=driver.min_gap_m, max_accel_mps2=driver.max_accel_mps2,
                     comfort_decel_mps2=driver.comfort_decel_mps2, accel_exponent=driver.accel_exponent)


def ref_simulate(plan, road, driver, num_frames, mobil=None, period=10):
    """Frame by frame: (s, v, d, d_rate) [T, V] and the (x, y, heading, lane) of the scene."""
    f = lambda a: np.asarray(a, float).copy()  # noqa: E731
    s, v = f(plan.s_m), f(plan.speed_mps)
    lc_start, d_from, d_to, dur = f(plan.lc_start_s), f(plan.d_from_m), f(plan.d_to_m), f(plan.lc_duration_s)
    length, width = f(plan.length_m), f(plan.width_m)
    background = np.asarray(plan.role) == scene.BACKGROUND
    idm = _idm_params(*ref_idm(plan, driver), driver)
    out = {k: [] for k in ("s", "v", "d", "d_rate")}
    for k in range(num_frames):
        t = k * DT
        d = np.array([float(scene.quintic_lateral_offset_m(t, lc_start[i], dur[i], d_from[i], d_to[i])) for i in range(len(s))])
        rate = np.array([float(scene.quintic_lateral_speed_mps(t, lc_start[i], dur[i], d_from[i], d_to[i])) for i in range(len(s))])
        announced = background & (t >= lc_start) & (t < lc_start + dur)
        gap, lead_v = ref_leaders(s, d, v, length, width, driver.lateral_margin_m, np.where(announced, d_to, d), W)
        a = np.maximum(np.asarray(scene.idm_acceleration(jnp.asarray(v), jnp.asarray(gap), jnp.asarray(lead_v), idm)),
                       -driver.max_brake_mps2)
        if mobil is not None and k % period == 0:
            free = background & (t >= lc_start + dur)
            now = {"s": s, "d": d, "centre": d_to, "v": v, "a": a, "length": length}
            starts, to = ref_starts(now, idm, free, mobil, int(road.num_lanes), W)
            lc_start = np.where(starts, t, lc_start)
            d_from = np.where(starts, d_to, d_from)
            d_to = np.where(starts, to, d_to)
        for name, value in (("s", s), ("v", v), ("d", d), ("d_rate", rate)):
            out[name].append(value.copy())
        v_next = v + a * DT
        step = np.where(v_next < 0.0, v**2 / (2.0 * np.where(v_next < 0.0, -a, 1.0)), 0.5 * (v + v_next) * DT)
        s, v = s + step, np.maximum(v_next, 0.0)
    out = {k: np.array(x) for k, x in out.items()}
    x, y, angle = (np.asarray(a) for a in scene.frenet_to_cartesian(road, out["s"], out["d"]))
    along = out["v"] * (1.0 - np.asarray(scene.curvature_1pm(road, out["s"])) * out["d"])
    still = (np.abs(along) + np.abs(out["d_rate"])) == 0.0
    heading = angle + np.arctan2(out["d_rate"], np.where(still, 1.0, along))
    return out, x, y, heading, np.asarray(scene.lane_index(road, out["d"]))


def _plan(rows):
    """VehiclePlan from rows (s, v, lane from, lane to, lc start, lc duration, length, width, kind, role)."""
    a = np.array(rows, dtype=float).T
    centre = lambda lane: (lane + 0.5) * W  # noqa: E731
    return scene.VehiclePlan(s_m=jnp.asarray(a[0]), speed_mps=jnp.asarray(a[1]), d_from_m=jnp.asarray(centre(a[2])),
                       d_to_m=jnp.asarray(centre(a[3])), lc_start_s=jnp.asarray(a[4]), lc_duration_s=jnp.asarray(a[5]),
                       length_m=jnp.asarray(a[6]), width_m=jnp.asarray(a[7]),
                       kind=jnp.asarray(a[8], jnp.int32), role=jnp.asarray(a[9], jnp.int32))


# On the curve: an ego behind a lead, a cut-in from the left, a background car closing on a truck
# stopped in the right lane (it brakes to a stop: the ballistic step's v = 0 branch; with MOBIL it
# also changes lanes), a free background car far ahead, and in lane 3 a background car behind a
# slower one.
PLAN = _plan([
    (130.0, 25.0, 1, 1, 0.0, 4.0, 4.6, 1.85, scene.CAR, scene.EGO),
    (168.0, 24.0, 1, 1, 0.0, 4.0, 4.4, 1.80, scene.CAR, scene.LEAD),
    (150.0, 26.5, 2, 1, 1.2, 3.5, 5.0, 2.00, scene.VAN, scene.TARGET),
    (205.0, 0.0, 0, 0, 0.0, 4.0, 12.0, 2.50, scene.TRUCK, scene.ADJACENT),
    (170.0, 20.0, 0, 0, 0.0, 4.0, 4.5, 1.90, scene.CAR, scene.BACKGROUND),
    (420.0, 27.0, 2, 2, 0.0, 4.0, 4.7, 1.80, scene.CAR, scene.BACKGROUND),
    (140.0, 29.0, 3, 3, 0.0, 4.0, 4.5, 1.80, scene.CAR, scene.BACKGROUND),
    (171.0, 21.0, 3, 3, 0.0, 4.0, 4.8, 1.90, scene.CAR, scene.BACKGROUND),
])
MOBIL = scene.MOBILParams(politeness=0.15, threshold_mps2=0.1, safe_decel_mps2=3.5, keep_right_bias_mps2=0.05)


def test_the_plan_starts_followers_in_steady_state_and_free_vehicles_at_their_speed():
    # The plan covers every branch of the start's IDM: followers (ratio x v), a clipped headway,
    # free vehicles, and a vehicle at rest whose desired speed is the floor. (The trajectories
    # below are simulated with these parameters.)
    v0, headway = ref_idm(PLAN, DRIVER)
    follows = np.isclose(v0, DRIVER.follower_speed_ratio * np.maximum(np.asarray(PLAN.speed_mps), 1.0))
    assert follows.any() and (~follows).any()
    assert np.any(headway == DRIVER.min_time_headway_s) and np.any(headway == DRIVER.time_headway_s)
    assert v0[3] in (DRIVER.follower_speed_ratio * MIN_DESIRED_SPEED_MPS, MIN_DESIRED_SPEED_MPS)


@pytest.mark.parametrize(("with_mobil", "period"), [(False, 7), (True, 7), (True, None)])
def test_trajectories_frame_by_frame(with_mobil, period):
    frames = 60  # not 61: at 6.0 s car 4's change (from 4.0 s) is half done, on the lane boundary
    mobil = MOBIL if with_mobil else None
    want, x, y, heading, lane = ref_simulate(PLAN, ROAD, DRIVER, frames, mobil, period or 10)
    if period is None:  # the default: a decision every 10 frames
        sim = jax.jit(scene.simulate_plan, static_argnums=(2, 3, 4))(PLAN, ROAD, DRIVER, frames, DT, mobil)
        # Car 4 becomes free to decide at 4.0 s (its plan's lane change of 4 s from t = 0 ends),
        # frame 40, a decision frame: it starts its change right there.
        assert want["d"][40, 4] == want["d"][0, 4] != want["d"][41, 4]
    else:
        sim = jax.jit(scene.simulate_plan, static_argnums=(2, 3, 4, 6))(PLAN, ROAD, DRIVER, frames, DT, mobil, period)
    for name, got in (("s", sim.s_m), ("v", sim.speed_mps), ("d", sim.d_m)):
        np.testing.assert_allclose(np.asarray(got), want[name], rtol=1e-10, atol=1e-9, err_msg=name)
    np.testing.assert_allclose(np.asarray(sim.x_m), x, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(np.asarray(sim.y_m), y, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(np.asarray(sim.heading_rad), heading, rtol=1e-10, atol=1e-9)
    np.testing.assert_array_equal(np.asarray(sim.lane), lane)
    np.testing.assert_allclose(np.asarray(sim.road_angle_rad),
                               np.asarray(scene.frenet_to_cartesian(ROAD, want["s"], want["d"])[2]), rtol=1e-12)
    for name in ("length_m", "width_m", "kind", "role"):
        np.testing.assert_array_equal(np.asarray(getattr(sim, name)), np.asarray(getattr(PLAN, name)), err_msg=name)
    assert np.asarray(sim.present).all() and sim.present.shape == (8,) and sim.dt_s == DT
    # What the scene exercises: a stop (v = 0 reached mid-run), the cut-in, and with MOBIL a
    # background change decided on a multiple of the period.
    assert want["v"][-1, 4] == 0.0 and want["v"][frames // 2, 4] > 0.0
    assert abs(want["d"][-1, 2] - 1.5 * W) < 1e-9
    moved = np.abs(want["d"][-1] - want["d"][0]) > 1.0
    assert moved[4] == with_mobil and not moved[[0, 1, 3, 5, 6, 7]].any()


@pytest.mark.parametrize(("edit", "culprit"), [
    ({"ego": {"lane": 3}, "target_lane": 4, "adjacent_lane": 2}, "ego.lane 3"),
    ({"ego": {"lane": 2}, "target_lane": 3, "adjacent_lane": 1}, "target_lane 3"),
    ({"adjacent_lane": 3}, "adjacent_lane 3"),
    ({"adjacent_lane": -1}, "adjacent_lane -1"),
])
def test_a_lane_off_the_road_and_no_variants_are_refused_naming_them(edit, culprit):
    cfg = scene.load_scenario("sc05")  # the straight road: lanes 0..2
    if "ego" in edit:
        edit = {**edit, "ego": {**dataclasses.asdict(cfg.ego), **edit["ego"]}}
    with pytest.raises(InputError, match=f"^sc05: {culprit} .*'straight' \\(0..2\\)"):
        scene.simulate_scenario(replace(cfg, **edit), 2, jax.random.key(0))
    for bad in (0, -1, 2.0):
        with pytest.raises(InputError, match="num_variants"):
            scene.simulate_scenario(cfg, bad, jax.random.key(0))


def test_a_speed_offset_is_a_config_edit_of_the_ego_speed():
    """A number (a Python float, or a numpy scalar, which is one) moves the ego's start speed, and
    with it every start speed, as editing ego.speed_kmh does; the scene keeps its float type."""
    cfg, key = scene.load_scenario("sc01"), jax.random.key(4)
    base = scene.simulate_scenario(cfg, 3, key)
    ego = {**dataclasses.asdict(cfg.ego)}
    ego["speed_kmh"] = {k: v + 7.2 for k, v in ego["speed_kmh"].items()}
    edited = scene.simulate_scenario(replace(cfg, ego=ego), 3, key)
    for offset in (7.2, np.float64(7.2)):
        moved = scene.simulate_scenario(cfg, 3, key, speed_offset_kmh=offset)
        assert moved.speed_mps.dtype == moved.s_m.dtype == jnp.float32, type(offset)
        np.testing.assert_allclose(np.asarray(moved.speed_mps[:, 0]), np.asarray(base.speed_mps[:, 0]) + 2.0, rtol=1e-6)
        np.testing.assert_allclose(np.asarray(moved.speed_mps), np.asarray(edited.speed_mps), rtol=1e-5, atol=1e-4)
        np.testing.assert_allclose(np.asarray(moved.s_m), np.asarray(edited.s_m), rtol=1e-5, atol=1e-3)


def _variants(nums, road, driver, key, n, frames, mobil, period):
    """Variant k of n: the plan drawn from the k-th of n keys (the nominal for k = 0), simulated."""
    def one(k, nominal):
        return scene.simulate_plan(scene.draw_plan(nums, k, nominal), road, driver, frames, mobil=mobil, mobil_period_frames=period)
    return jax.jit(jax.vmap(one))(jax.random.split(key, n), jnp.arange(n) == 0)


@pytest.mark.parametrize(("decision_period_s", "period", "other"), [(0.1, 1, 2), (0.3, 3, 1)])
def test_background_traffic_changes_lanes_by_the_models_mobil_at_its_decision_period(decision_period_s, period, other):
    cfg = replace(scene.load_scenario("sc05"), background={"count": 6, "spacing_m": 25.0})  # close enough to interact
    models = scene.load_vehicle_models()
    models = dataclasses.replace(models, mobil=dataclasses.replace(
        models.mobil, politeness=0.05, threshold_mps2=0.05, keep_right_bias_mps2=0.0, decision_period_s=decision_period_s))
    key, n = jax.random.key(2), 2
    got = scene.simulate_scenario(cfg, n, key, models=models, dtype=jnp.float64)
    road = scene.load_road(cfg.road)
    nums = scene.scenario_numbers(cfg, models, road, jnp.float64)
    frames = round(cfg.duration_s / scene.SCENE_DT_S) + 1
    mobil = scene.MOBILParams(politeness=jnp.asarray(0.05), threshold_mps2=jnp.asarray(0.05),
                        safe_decel_mps2=jnp.asarray(models.mobil.safe_decel_mps2), keep_right_bias_mps2=jnp.asarray(0.0))
    want = _variants(nums, road, models.driver, key, n, frames, mobil, period)  # decision_period_s / 0.1 s
    for name in ("s_m", "d_m", "speed_mps"):  # (lanes to the rounding of d on a lane boundary)
        np.testing.assert_allclose(np.asarray(getattr(got, name)), np.asarray(getattr(want, name)), rtol=1e-12,
                                   atol=1e-9, err_msg=name)
    background = np.asarray(got.role[0]) == scene.BACKGROUND
    assert np.any(np.abs(np.diff(np.asarray(got.lane)[:, :, background], axis=1)) > 0)  # some change lanes
    elsewhen = _variants(nums, road, models.driver, key, n, frames, mobil, other)
    assert np.abs(np.asarray(elsewhen.d_m) - np.asarray(got.d_m)).max() > 1e-3
    without = scene.simulate_scenario(replace(cfg, background={"count": 6, "spacing_m": 25.0, "mobil": False}), n, key,
                                models=models, dtype=jnp.float64)
    kept = np.asarray(without.d_m[:, :, background])  # without MOBIL every background car keeps its lane
    np.testing.assert_array_equal(kept, np.broadcast_to(np.asarray(want.d_m[:, :1, background]), kept.shape))


def test_a_platoon_started_in_equilibrium_stays_there():
    """Five cars 50 m apart at 20 m/s: desired speeds make 50 m the IDM equilibrium gap.

    The leader's free-road interaction term (s*/1e4 m)^2 ~ 1e-5 is the only drift."""
    driver = scene.load_vehicle_models().driver
    f = lambda v: jnp.full((5,), v, jnp.float64)  # noqa: E731
    plan = scene.VehiclePlan(
        s_m=jnp.arange(5.0) * (50.0 + 4.6), speed_mps=f(20.0), d_from_m=f(5.49), d_to_m=f(5.49),
        lc_start_s=f(scene.NO_LANE_CHANGE_S), lc_duration_s=f(1.0), length_m=f(4.6), width_m=f(1.8),
        kind=jnp.zeros(5, jnp.int32), role=jnp.full(5, 5, jnp.int32),
    )
    sc = jax.jit(scene.simulate_plan, static_argnums=(2, 3))(plan, scene.load_road("straight"), driver, 601)
    gaps = np.diff(np.asarray(sc.s_m), axis=-1) - 4.6
    assert np.allclose(gaps, 50.0, atol=0.05) and np.allclose(sc.speed_mps, 20.0, atol=1e-3)
    assert gaps.min() >= driver.min_gap_m


def test_the_ego_speeds_gradient_matches_finite_differences():
    """How far the ego gets in 10 s of Sc-01, against its start speed (float64)."""
    cfg = scene.load_scenario("sc01")
    road, models = scene.load_road(cfg.road), scene.load_vehicle_models()
    plan = scene.draw_plan(scene.scenario_numbers(cfg, models, road, jnp.float64), jax.random.key(0), jnp.asarray(True))

    def ego_end_s(speed):
        p = dataclasses.replace(plan, speed_mps=plan.speed_mps.at[0].set(speed))
        return scene.simulate_plan(p, road, models.driver, 101).s_m[-1, 0]

    value_and_grad = jax.jit(jax.value_and_grad(ego_end_s))  # one compilation serves both
    v = plan.speed_mps[0]
    _, grad = value_and_grad(v)
    fd = (value_and_grad(v + 1e-5)[0] - value_and_grad(v - 1e-5)[0]) / 2e-5
    assert np.isfinite(grad) and abs(grad - fd) < 1e-5 * max(1.0, abs(fd))
    assert 0.0 < grad < 10.0  # starting faster gets further, less than 10 s worth of it


def test_standstill_and_touching_vehicles_give_finite_gradients():
    """The extremes: a vehicle at rest, a pair bumper to bumper, a lane change under way."""
    f = lambda *v: jnp.array(v, jnp.float64)  # noqa: E731
    plan = scene.VehiclePlan(
        s_m=f(100.0, 104.6, 200.0), speed_mps=f(0.0, 15.0, 20.0), d_from_m=f(5.49, 5.49, 9.15),
        d_to_m=f(5.49, 5.49, 5.49), lc_start_s=f(scene.NO_LANE_CHANGE_S, scene.NO_LANE_CHANGE_S, 0.5),
        lc_duration_s=f(1.0, 1.0, 3.0), length_m=f(4.6, 4.6, 4.6), width_m=f(1.8, 1.8, 1.8),
        kind=jnp.zeros(3, jnp.int32), role=jnp.full(3, 5, jnp.int32),
    )

    def total(floats):
        sc = scene.simulate_plan(dataclasses.replace(plan, **floats), scene.load_road("us101"), scene.load_vehicle_models().driver, 61)
        return sum(jnp.sum(a) for a in (sc.x_m, sc.y_m, sc.heading_rad, sc.speed_mps))

    names = ("s_m", "speed_mps", "d_from_m", "d_to_m", "lc_start_s", "lc_duration_s")
    value, grads = jax.jit(jax.value_and_grad(total))({k: getattr(plan, k) for k in names})
    assert np.isfinite(value) and all(np.all(np.isfinite(grads[name])) for name in names)
