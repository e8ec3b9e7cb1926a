"""Training traffic: no collisions, on the road, lane changes of one lane width, IDM gaps, determinism."""

from __future__ import annotations

import jax
import numpy as np
import pytest

from diffsense.config import replace
from diffsense.scene import TrafficConfig
from diffsense.train import simulate_batch, simulation_keys

LANE_W = 3.66


def small_config(**sampling) -> TrafficConfig:
    """Dense, short, small: 3 lanes x 5 vehicles, 29 s recorded (compiles once per module)."""
    base = TrafficConfig()
    return replace(
        base,
        road=replace(base.road, num_lanes=3, vehicles_per_lane=5),
        traffic=replace(base.traffic, density_veh_per_km_lane=(25.0, 70.0)),
        sampling=replace(base.sampling, **({"warmup_s": 10.0, "window_s": 20.0, "instant_every_s": 2.0, "simulations_per_shard": 4} | sampling)),
    )


CFG = small_config()
NUM_SIMS = 12


def simulate(key, num_sims=NUM_SIMS):
    """Batches of 4 simulations, the shape the dataset tests compile too."""
    parts = [simulate_batch(CFG, simulation_keys(key, first, 4)) for first in range(0, num_sims, 4)]
    return jax.tree_util.tree_map(lambda *a: np.concatenate([np.asarray(x) for x in a]), *parts)


@pytest.fixture(scope="module")
def traffic():
    return simulate(jax.random.key(7))


def bumper_gaps(traj, n):
    """Gap [T, i, j] from i's front bumper to j's rear, j ahead of i on the ring (nearest image)."""
    s, ring, length = traj.s_m[n], traj.vehicles.ring_length_m[n], traj.vehicles.length_m[n]
    ahead = np.mod(s[:, None, :] - s[:, :, None], ring)
    return ahead - 0.5 * (length[None, :, None] + length[None, None, :]), ahead


def min_gap_sharing_a_lane(traj, n):
    """Smallest bumper gap [m] over frames between vehicles sharing a lane in simulation n.

    A vehicle changing lanes occupies both: the lane it leaves and the one it enters.
    """
    lane, target = traj.lane[n], traj.target_lane[n]
    share = (
        (lane[:, :, None] == lane[:, None, :]) | (lane[:, :, None] == target[:, None, :])
        | (target[:, :, None] == lane[:, None, :]) | (target[:, :, None] == target[:, None, :])
    )
    share &= ~np.eye(lane.shape[1], dtype=bool)[None]
    gap, ahead = bumper_gaps(traj, n)
    front = share & (ahead <= 0.5 * traj.vehicles.ring_length_m[n])  # each pair once, from behind
    return np.where(front, gap, np.inf).min()


def test_no_collisions_between_vehicles_sharing_a_lane(traffic):
    smallest = min(min_gap_sharing_a_lane(traffic, n) for n in range(NUM_SIMS))
    assert 0.0 < smallest < np.inf, f"bumper gaps down to {smallest:.3f} m"


def test_vehicles_stay_on_the_road(traffic):
    half_w = 0.5 * traffic.vehicles.width_m[:, None, :]
    assert (traffic.d_m - half_w >= 0.0).all()
    assert (traffic.d_m + half_w <= CFG.road.num_lanes * LANE_W).all()
    assert (traffic.speed_mps >= 0.0).all() and np.isfinite(traffic.s_m).all()
    assert (np.diff(traffic.s_m, axis=1) >= 0.0).all()  # never reverses


def test_lane_changes_end_one_lane_width_away_in_their_direction(traffic):
    events = 0
    for n in range(NUM_SIMS):
        lane, target, d = traffic.lane[n], traffic.target_lane[n], traffic.d_m[n]
        for v in range(lane.shape[1]):
            starts = np.nonzero((target[1:, v] != target[:-1, v]) & (target[1:, v] != lane[1:, v]))[0] + 1
            for t0 in starts:
                ends = np.nonzero(lane[t0:, v] == target[t0, v])[0]
                if len(ends) == 0:
                    continue  # still changing at the end of the recording
                t1 = t0 + ends[0]
                moved = d[t1, v] - d[t0 - 1, v]
                direction = np.sign(target[t0, v] - lane[t0, v])
                assert abs(abs(moved) - LANE_W) <= 0.05 * LANE_W, (n, v, t0, moved)
                assert np.sign(moved) == direction
                duration = (t1 - t0 + 1) * 0.1
                assert CFG.lane_change.duration_s[0] - 0.11 <= duration <= CFG.lane_change.duration_s[1] + 0.11
                events += 1
    assert events >= 5, f"only {events} complete lane changes: the test would prove little"


def test_idm_followers_keep_the_minimum_gap_in_steady_state():
    base = TrafficConfig()
    cfg = replace(
        base,
        road=replace(base.road, num_lanes=1, vehicles_per_lane=8),
        traffic=replace(base.traffic, density_veh_per_km_lane=(20.0, 30.0), speed_change_rate_per_s=0.0),
        sampling=replace(base.sampling, warmup_s=120.0, window_s=2.0),
    )
    traj = jax.tree_util.tree_map(np.asarray, simulate_batch(cfg, simulation_keys(jax.random.key(3), 0, 4)))
    for n in range(4):
        gap, ahead = bumper_gaps(traj, n)
        ring = traj.vehicles.ring_length_m[n]
        ahead = np.where(np.eye(8, dtype=bool)[None], np.inf, ahead)
        leader = np.argmin(ahead, axis=2)  # [T, i]
        lead_gap = np.take_along_axis(gap, leader[:, :, None], axis=2)[:, :, 0]
        s0 = traj.vehicles.idm.min_gap_m[n]
        assert (lead_gap >= s0[None, :]).all(), (lead_gap - s0).min()
        # Steady: everybody at the same speed, no one accelerating.
        v = traj.speed_mps[n]
        assert np.ptp(v[-1]) < 0.05 and np.abs(v[-1] - v[-10]).max() < 0.01
        assert ring > 0


@pytest.mark.slow
def test_shipped_config_is_collision_free_and_on_the_road():
    from diffsense.config import load_default

    cfg = load_default(TrafficConfig, "traffic/default.toml")
    traj = jax.tree_util.tree_map(np.asarray, simulate_batch(cfg, simulation_keys(jax.random.key(0), 0, 32)))
    assert min(min_gap_sharing_a_lane(traj, n) for n in range(32)) > 0.0
    half_w = 0.5 * traj.vehicles.width_m[:, None, :]
    assert (traj.d_m - half_w >= 0.0).all() and (traj.d_m + half_w <= cfg.road.num_lanes * cfg.road.lane_width_m).all()
    assert (traj.target_lane != traj.lane).any()  # lane changes happen


@pytest.mark.slow
def test_extremes_of_the_config_ranges_stay_finite_and_collision_free():
    base = TrafficConfig()
    cfg = replace(
        base,
        road=replace(base.road, num_lanes=2, vehicles_per_lane=9),
        traffic=replace(
            base.traffic, density_veh_per_km_lane=(150.0, 150.0), desired_speed_mps=(60.0, 60.0),
            speed_change_rate_per_s=1.0, speed_change_factor=(0.01, 3.0), kind_probabilities=(0.0, 0.0, 1.0),
        ),
        lane_change=replace(base.lane_change, duration_s=(0.5, 0.5), cooldown_s=0.0, route_change_rate_per_s=5.0),
        sampling=replace(base.sampling, warmup_s=2.0, window_s=10.0),
    )
    traj = jax.tree_util.tree_map(np.asarray, simulate_batch(cfg, simulation_keys(jax.random.key(5), 0, 4)))
    assert all(np.isfinite(a).all() for a in jax.tree_util.tree_leaves(traj) if a.dtype.kind == "f")
    assert (traj.vehicles.ring_length_m >= 60.0).all()
    assert min(min_gap_sharing_a_lane(traj, n) for n in range(4)) > 0.0


def test_same_key_same_traffic_bit_for_bit(traffic):
    again = simulate(jax.random.key(7))
    for a, b in zip(jax.tree_util.tree_leaves(traffic), jax.tree_util.tree_leaves(again)):
        np.testing.assert_array_equal(a, b)
    other = simulate(jax.random.key(8), 4)
    assert not np.array_equal(other.s_m, traffic.s_m[:4])


def test_simulation_is_float32_and_finite(traffic):
    # simulate_batch is jax.jit(vmap(simulate_traffic)): the fixture already proves it compiles.
    assert traffic.s_m.dtype == np.float32 and traffic.d_m.dtype == np.float32
    assert traffic.lane.dtype == np.int32
    assert all(np.isfinite(a).all() for a in jax.tree_util.tree_leaves(traffic) if a.dtype.kind == "f")
