"""Training traffic's start and recording against values written out by hand: the number of
steps, the initial placement on the ring (every draw inside its kind's
interval, bumper gaps of s0 plus a share of the free length closing the ring, speeds at the
equilibrium of each gap), the lateral offset of a lane change and the recorded frames of a
simulation against a loop over `traffic_step`.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense import scene
from diffsense.config import replace

BASE = scene.TrafficConfig()
CFG = replace(
    BASE,
    road=replace(BASE.road, num_lanes=3, lane_width_m=3.5, vehicles_per_lane=5),
    traffic=replace(BASE.traffic, density_veh_per_km_lane=(30.0, 60.0), desired_speed_spread=0.3,
                    kind_probabilities=(0.5, 0.25, 0.25), accel_exponent=3.5),
    lane_change=replace(BASE.lane_change, duration_s=(2.5, 4.5), politeness=(0.15, 0.55)),
    sampling=replace(BASE.sampling, warmup_s=1.0, window_s=0.4),
)


def test_steps_span_warm_up_4_s_before_the_window_and_5_s_after():
    assert scene.num_steps(BASE) == (200, 491)  # 20 s; (4 + 40 + 5) s at 10 Hz, both ends
    assert scene.num_steps(CFG) == (10, 95)  # 1 s; (4 + 0.4 + 5) s


def steady_speed(gap, p):
    """The speed at which `gap` [m] is IDM's steady-state gap, bisected to the last bit."""
    lo, hi = 0.0, p.desired_speed_mps
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        free = max(1.0 - (mid / p.desired_speed_mps) ** p.accel_exponent, 0.0)
        lo, hi = (mid, hi) if p.min_gap_m + mid * p.time_headway_s < gap * math.sqrt(free) else (lo, mid)
    return lo


@pytest.fixture(scope="module")
def start():
    return scene.init_traffic(CFG, jax.random.key(11), jnp.float64)


def test_every_vehicle_is_drawn_inside_its_kinds_intervals(start):
    vehicles, _ = start
    kinds = np.asarray(vehicles.kind)
    assert set(kinds) == {0, 1, 2}
    spread = CFG.traffic.desired_speed_spread
    mean_v0 = float(vehicles.mean_desired_speed_mps)
    assert CFG.traffic.desired_speed_mps[0] <= mean_v0 <= CFG.traffic.desired_speed_mps[1]
    for i, k in enumerate(kinds):
        kind = CFG.kinds[k]
        for field, values in (("length_m", vehicles.length_m), ("width_m", vehicles.width_m),
                              ("time_headway_s", vehicles.idm.time_headway_s), ("min_gap_m", vehicles.idm.min_gap_m),
                              ("max_accel_mps2", vehicles.idm.max_accel_mps2),
                              ("comfort_decel_mps2", vehicles.idm.comfort_decel_mps2)):
            lo, hi = getattr(kind, field)
            assert lo <= float(values[i]) <= hi, (i, field)
        assert float(vehicles.max_desired_speed_mps[i]) == kind.max_desired_speed_mps
        v0 = float(vehicles.idm.desired_speed_mps[i])
        assert v0 == kind.max_desired_speed_mps or (1 - spread) * mean_v0 <= v0 <= (1 + spread) * mean_v0
        assert v0 <= kind.max_desired_speed_mps
        assert CFG.lane_change.politeness[0] <= float(vehicles.politeness[i]) <= CFG.lane_change.politeness[1]
    np.testing.assert_array_equal(np.asarray(vehicles.idm.accel_exponent), 3.5)


def test_the_start_is_every_lane_closed_around_the_ring_at_equilibrium(start):
    vehicles, state = start
    n, per_lane = CFG.num_vehicles, CFG.road.vehicles_per_lane
    ring = float(vehicles.ring_length_m)
    s, length = np.asarray(state.s_m), np.asarray(vehicles.length_m)
    s0 = np.asarray(vehicles.idm.min_gap_m)
    lo_density, hi_density = CFG.traffic.density_veh_per_km_lane
    need = (length + s0).reshape(3, per_lane).sum(axis=1)
    assert ring >= 1.05 * need.max() - 1e-9 and ring >= per_lane * 1000.0 / hi_density - 1e-9
    assert ring <= per_lane * 1000.0 / lo_density or ring == pytest.approx(1.05 * need.max(), rel=1e-12)
    np.testing.assert_array_equal(np.asarray(state.lane), np.arange(n) // per_lane)
    np.testing.assert_array_equal(np.asarray(state.target_lane), np.asarray(state.lane))
    for lane in range(3):
        i = np.arange(lane * per_lane, (lane + 1) * per_lane)
        leader = np.roll(i, -1)  # each vehicle follows the next one of its lane; the last, the first
        gap = np.mod(s[leader] - s[i], ring) - 0.5 * (length[i] + length[leader])
        assert np.all(gap >= s0[i] - 1e-9)
        assert gap.sum() + length[i].sum() == pytest.approx(ring, rel=1e-12)  # once around
        for j, g in zip(i, gap):
            p = scene.IDMParams(*(float(np.asarray(getattr(vehicles.idm, f))[j]) for f in scene.IDMParams.__dataclass_fields__))
            want = steady_speed(g, p)
            assert want - p.desired_speed_mps * 2.0**-18 <= float(state.speed_mps[j]) <= want + 1e-9
    np.testing.assert_array_equal(np.asarray(state.since_change_s), 1e3)  # free to change at once
    np.testing.assert_array_equal(np.asarray(state.change_duration_s), CFG.lane_change.duration_s[0])
    np.testing.assert_array_equal(np.asarray(state.desired_speed_mps), np.asarray(vehicles.idm.desired_speed_mps))
    assert set(np.asarray(state.preferred_lane)) <= {0, 1, 2}


def lane_layout(vehicles, state, per_lane):
    """Per lane (rows): the first vehicle's rear [m] and each vehicle's bumper gap beyond s0 to
    the next one of its lane [m]."""
    s, length, s0 = (np.asarray(x).reshape(-1, per_lane) for x in (state.s_m, vehicles.length_m, vehicles.idm.min_gap_m))
    ahead = np.mod(np.roll(s, -1, axis=1) - s, float(vehicles.ring_length_m))
    return s[:, 0] - 0.5 * length[:, 0], ahead - 0.5 * (length + np.roll(length, -1, axis=1)) - s0


def test_over_many_draws_lanes_start_anywhere_and_free_length_is_shared_by_weights_from_half_to_one_and_a_half():
    draws = jax.jit(jax.vmap(lambda key: scene.init_traffic(CFG, key, jnp.float64)))(jax.random.split(jax.random.key(2), 64))
    firsts, ratios = [], []
    for n in range(64):
        vehicles, state = jax.tree_util.tree_map(lambda x, n=n: x[n], draws)
        first, extra = lane_layout(vehicles, state, CFG.road.vehicles_per_lane)
        firsts.extend(first / float(vehicles.ring_length_m))
        ratios.extend(extra.max(axis=1) / extra.min(axis=1))
    assert 0.0 <= min(firsts) < 0.05 and 0.95 < max(firsts) < 1.0  # a lane's offset is U(0, ring)
    assert max(ratios) <= 3.0 and max(ratios) > 2.5  # shares of U(0.5, 1.5) weights: at most 3 to 1


KIND_FIELDS = ("length_m", "width_m", "time_headway_s", "min_gap_m", "max_accel_mps2", "comfort_decel_mps2")


def test_over_many_draws_each_size_and_driver_parameter_spans_its_interval_independently():
    """Where each of the six per-kind draws lies in its kind's interval (0 = lo, 1 = hi), over 64
    simulations: every field reaches both ends, and no two fields share their random numbers."""
    vehicles, _ = jax.jit(jax.vmap(lambda key: scene.init_traffic(CFG, key, jnp.float64)))(
        jax.random.split(jax.random.key(8), 64))
    kind = np.asarray(vehicles.kind).ravel()
    quantiles = []
    for field in KIND_FIELDS:
        value = np.asarray(getattr(vehicles, field) if field in ("length_m", "width_m")
                           else getattr(vehicles.idm, field)).ravel()
        lo, hi = (np.array([getattr(k, field)[end] for k in CFG.kinds])[kind] for end in (0, 1))
        q = (value - lo) / (hi - lo)
        assert q.min() >= 0.0 and q.max() <= 1.0 + 1e-12 and q.min() < 0.01 and q.max() > 0.99, field
        quantiles.append(q)
    correlation = np.corrcoef(quantiles)
    assert np.abs(correlation - np.eye(6)).max() < 0.15, correlation


def test_a_density_too_high_for_the_drawn_vehicles_lengthens_the_ring_to_1_05_of_the_longest_lane():
    trucks = replace(CFG, traffic=replace(CFG.traffic, density_veh_per_km_lane=(70.0, 80.0),
                                          kind_probabilities=(0.0, 0.0, 1.0)))
    vehicles, state = scene.init_traffic(trucks, jax.random.key(4), jnp.float64)
    need = (np.asarray(vehicles.length_m) + np.asarray(vehicles.idm.min_gap_m)).reshape(3, -1).sum(axis=1)
    assert 5 * 1000.0 / 70.0 < 1.05 * need.max()  # the density alone would pack them tighter than s0
    assert float(vehicles.ring_length_m) == pytest.approx(1.05 * need.max(), rel=1e-12)
    _, extra = lane_layout(vehicles, state, 5)
    assert extra.min() >= -1e-9


@pytest.mark.parametrize(("since_s", "progress"), [(0.0, 0.0), (1.0, 0.103515625), (2.0, 0.5), (4.0, 1.0),
                                                   (9.0, 1.0)])
def test_lateral_offset_follows_the_quintic_from_lane_to_target(since_s, progress):
    # 4 s from lane 2 to lane 1 (3.5 m lanes): 10 t^3 - 15 t^4 + 6 t^5 of the way at t = since / 4.
    state = scene.TrafficState(*(jnp.asarray([x]) for x in (0.0, 20.0)), lane=jnp.asarray([2]), target_lane=jnp.asarray([1]),
                         since_change_s=jnp.asarray([since_s]), change_duration_s=jnp.asarray([4.0]),
                         desired_speed_mps=jnp.asarray([30.0]), preferred_lane=jnp.asarray([1]))
    d = float(scene.lateral_offset_m(state, 3.5)[0])
    assert d == pytest.approx(2.5 * 3.5 - progress * 3.5, abs=1e-12)
    traj = scene.TrafficTrajectories(*(jnp.asarray([[x]]) for x in (0.0, d, 20.0, 2, 1)), vehicles=None)
    lane = traj.centre_lane(3.5)
    assert lane.dtype == jnp.int32 and int(lane[0, 0]) == (2 if d >= 7.0 else 1)


def test_a_simulation_records_the_states_after_the_warm_up_step_by_step():
    key = jax.random.key(5)
    got = jax.jit(scene.simulate_traffic, static_argnums=(0, 2))(CFG, key, jnp.float64)
    init_key, run_key = jax.random.split(key)
    vehicles, state = scene.init_traffic(CFG, init_key, jnp.float64)
    warmup, recorded = scene.num_steps(CFG)
    step = jax.jit(scene.traffic_step, static_argnums=0)
    frames = []
    for k, step_key in enumerate(jax.random.split(run_key, warmup + recorded)):
        if k >= warmup:
            frames.append(state)
        state = step(CFG, vehicles, state, step_key)
    assert got.s_m.shape == (recorded, CFG.num_vehicles) and got.dt_s == 0.1
    for name in ("s_m", "speed_mps", "lane", "target_lane"):
        np.testing.assert_allclose(np.asarray(getattr(got, name)), np.stack([getattr(f, name) for f in frames]),
                                   rtol=1e-12, err_msg=name)
    np.testing.assert_allclose(np.asarray(got.d_m), np.stack([scene.lateral_offset_m(f, 3.5) for f in frames]), rtol=1e-12)
    np.testing.assert_array_equal(np.asarray(got.vehicles.length_m), np.asarray(vehicles.length_m))
