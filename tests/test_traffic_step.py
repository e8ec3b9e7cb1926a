"""One step of the training traffic (`traffic_step`) restated as plain loops over vehicles.

The restatement follows `diffsense/scene/_traffic.py`'s docstring: leader and follower on the ring
in the lanes right of, at and left of each vehicle's own (a changing vehicle occupies both of its
lanes), IDM towards the leader of every lane a vehicle occupies with the comfortable-deceleration
cap above the desired speed, MOBIL per side with the old follower's gain, the keep-right and route
biases, a bumper gap above min_gap_m to both new neighbours and the cool-down, two close starters
into a common lane resolved to the lower index, the drawn lane-change duration, the ballistic
update that stops at v = 0, the desired-speed and route redraws. The IDM acceleration and MOBIL's
formulas are written out from diffsense/scene/_idm.py's and _mobil.py's docstrings; the random
numbers are the step's own draw. States come from a simulation with frequent redraws and lane
changes, and each is stepped once by both, so one wrong rule shows at the step it acts. The
neighbour search on the ring and the start's equilibrium speed (private) are checked on their own.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_traffic_start import steady_speed

from diffsense import runtime, scene
from diffsense.config import replace
from diffsense.scene._traffic import _neighbours
from diffsense.scene._traffic_state import _equilibrium_speed

BASE = scene.TrafficConfig()
# 3 lanes x 4 vehicles, 40-80 m apart; parameters away from the defaults and from each other; redraws and
# route changes frequent, so every rule acts within a few dozen steps.
CFG = replace(
    BASE,
    road=replace(BASE.road, num_lanes=3, lane_width_m=3.5, vehicles_per_lane=4),
    traffic=replace(BASE.traffic, density_veh_per_km_lane=(12.0, 25.0), speed_change_rate_per_s=1.5,
                    speed_change_factor=(0.3, 1.4), kind_probabilities=(0.6, 0.2, 0.2)),
    lane_change=replace(BASE.lane_change, duration_s=(1.0, 2.5), politeness=(0.1, 0.6), threshold_mps2=0.07,
                        safe_decel_mps2=2.6, keep_right_bias_mps2=0.13, min_gap_m=1.3, cooldown_s=0.6,
                        conflict_distance_m=12.0, route_change_rate_per_s=2.0, route_bias_mps2=1.7),
)
DT_S = 0.1  # the traffic's step
IDM_FIELDS = ("desired_speed_mps", "time_headway_s", "min_gap_m", "max_accel_mps2", "comfort_decel_mps2",
              "accel_exponent")


def driver(vehicles, state, j) -> scene.IDMParams:
    p = vehicles.idm
    return scene.IDMParams(float(state.desired_speed_mps[j]), *(float(getattr(p, f)[j]) for f in IDM_FIELDS[1:]))


def idm_acceleration(v, gap, lead_v, p: scene.IDMParams):
    """IDM with gaps floored at 5 cm (touching bodies brake hard and finitely) [m/s2]."""
    v = max(v, 0.0)
    dynamic = v * p.time_headway_s + v * (v - lead_v) / (2.0 * math.sqrt(p.max_accel_mps2 * p.comfort_decel_mps2))
    wanted = p.min_gap_m + max(dynamic, 0.0)
    return p.max_accel_mps2 * (1.0 - (v / p.desired_speed_mps) ** p.accel_exponent - (wanted / max(gap, 0.05)) ** 2)


def idm_towards(v, length, p: scene.IDMParams, lead_dist, lead_len, lead_v, has_lead):
    gap = lead_dist - 0.5 * (length + lead_len) if has_lead else scene.FREE_ROAD_GAP_M
    accel = idm_acceleration(v, gap, lead_v if has_lead else v, p)
    free_road = p.max_accel_mps2 * (1.0 - (v / p.desired_speed_mps) ** p.accel_exponent)
    return accel + max(-p.comfort_decel_mps2 - free_road, 0.0)


def neighbours(state, ring):
    """leader[i][r], lead_dist[i][r], follower[i][r], foll_dist[i][r]; r = right, own, left;
    index None where the lane holds nobody else."""
    s, lane, target = (np.asarray(x) for x in (state.s_m, state.lane, state.target_lane))
    n = len(s)
    out = [[[None] * 3 for _ in range(n)] for _ in range(2)], [[[math.inf] * 3 for _ in range(n)] for _ in range(2)]
    (leader, follower), (lead_d, foll_d) = out
    for i in range(n):
        for r in range(3):
            for j in range(n):
                if j == i or (lane[j] != lane[i] + r - 1 and target[j] != lane[i] + r - 1):
                    continue
                ahead = (s[j] - s[i]) % ring
                behind = ring - ahead if ahead > 0 else 0.0
                if ahead < lead_d[i][r]:
                    leader[i][r], lead_d[i][r] = j, ahead
                if behind < foll_d[i][r]:
                    follower[i][r], foll_d[i][r] = j, behind
    return leader, lead_d, follower, foll_d


def ref_step(cfg, vehicles, state, key):
    """({"held": starters a close one held back, "incentive": [V, 3] MOBIL incentive per side with
    the route bias}, the next TrafficState as plain numpy arrays), vehicle by vehicle."""
    lc, n_lanes = cfg.lane_change, cfg.road.num_lanes
    g = {f: np.asarray(getattr(state, f)) for f in ("s_m", "speed_mps", "lane", "target_lane", "since_change_s",
                                                    "change_duration_s", "desired_speed_mps", "preferred_lane")}
    s, v, lane, target = g["s_m"], g["speed_mps"], g["lane"], g["target_lane"]
    length, ring = np.asarray(vehicles.length_m), float(vehicles.ring_length_m)
    n = len(s)
    p = [driver(vehicles, state, j) for j in range(n)]
    leader, lead_d, follower, foll_d = neighbours(state, ring)

    def towards(i, lead, dist):
        j = lead if lead is not None else 0
        return idm_towards(v[i], length[i], p[i], dist, length[j], v[j], lead is not None)

    accel_r = [[towards(i, leader[i][r], lead_d[i][r]) for r in range(3)] for i in range(n)]
    accel = [min(accel_r[i][1], accel_r[i][min(max(target[i] - lane[i] + 1, 0), 2)]) for i in range(n)]

    want, score, incentives = np.zeros((n, 3), bool), np.zeros((n, 3)), np.zeros((n, 3))
    for i in range(n):
        ready = target[i] == lane[i] and g["since_change_s"][i] >= g["change_duration_s"][i] + lc.cooldown_s
        old_f, own_l = follower[i][1], leader[i][1]
        o_gain = 0.0
        if old_f is not None:
            new_lead = own_l if own_l is not None and own_l != old_f else None
            after = idm_towards(v[old_f], length[old_f], p[old_f], foll_d[i][1] + lead_d[i][1],
                                length[own_l or 0], v[own_l or 0], new_lead is not None)
            o_gain = after - accel[old_f]
        pol = float(vehicles.politeness[i])
        for r in (0, 2):
            new_f, new_l = follower[i][r], leader[i][r]
            n_after = n_now = 0.0
            foll_gap = lead_gap = math.inf
            if new_f is not None:
                n_after = idm_towards(v[new_f], length[new_f], p[new_f], foll_d[i][r], length[i], v[i], True)
                n_now = accel[new_f]
                foll_gap = foll_d[i][r] - 0.5 * (length[i] + length[new_f])
            if new_l is not None:
                lead_gap = lead_d[i][r] - 0.5 * (length[i] + length[new_l])
            incentive = accel_r[i][r] - accel[i] + pol * (n_after - n_now + o_gain)
            towards_route = np.sign(g["preferred_lane"][i] - lane[i]) == r - 1
            incentive += lc.route_bias_mps2 if towards_route else -lc.route_bias_mps2
            bias = lc.keep_right_bias_mps2 if r == 2 else -lc.keep_right_bias_mps2
            want[i, r] = (ready and 0 <= lane[i] + r - 1 < n_lanes and lead_gap > lc.min_gap_m
                          and foll_gap > lc.min_gap_m and n_after >= -lc.safe_decel_mps2
                          and incentive > lc.threshold_mps2 + bias)
            score[i, r], incentives[i, r] = incentive - bias, incentive
    go_left = want[:, 2] & (~want[:, 0] | (score[:, 2] > score[:, 0]))
    starts = want[:, 0] | want[:, 2]
    new_target = np.where(starts, lane + np.where(go_left, 1, -1), target)
    lo, hi = np.minimum(lane, new_target), np.maximum(lane, new_target)
    blocked = np.zeros(n, bool)
    for i in range(n):
        for j in range(i):
            ahead = (s[j] - s[i]) % ring
            close = min(ahead, ring - ahead) < 0.5 * (length[i] + length[j]) + lc.conflict_distance_m
            blocked[i] |= starts[j] and close and lo[i] <= hi[j] and lo[j] <= hi[i]
    held = int(np.sum(starts & blocked))
    starts &= ~blocked
    new_target = np.where(starts, new_target, target)

    u = np.asarray(runtime.uniform(key, (5, n), state.s_m.dtype))
    (d_lo, d_hi), (f_lo, f_hi) = lc.duration_s, cfg.traffic.speed_change_factor
    duration = np.where(starts, d_lo + u[0] * (d_hi - d_lo), g["change_duration_s"])
    since = np.where(starts, 0.0, g["since_change_s"]) + DT_S
    accel = np.asarray(accel)
    v_new = v + accel * DT_S
    stop_m = v * v / (2.0 * np.maximum(-accel, 1e-3))
    new_v0 = np.minimum(float(vehicles.mean_desired_speed_mps) * (f_lo + (f_hi - f_lo) * u[2]),
                        np.asarray(vehicles.max_desired_speed_mps))
    new_pref = np.minimum(np.floor(u[4] * n_lanes).astype(int), n_lanes - 1)
    return {"held": held, "incentive": incentives}, {
        "s_m": s + np.where(v_new < 0.0, stop_m, v * DT_S + 0.5 * accel * DT_S**2),
        "speed_mps": np.maximum(v_new, 0.0),
        "lane": np.where((new_target != lane) & (since >= duration), new_target, lane),
        "target_lane": new_target, "since_change_s": since, "change_duration_s": duration,
        "desired_speed_mps": np.where(u[1] < cfg.traffic.speed_change_rate_per_s * DT_S, new_v0,
                                      g["desired_speed_mps"]),
        "preferred_lane": np.where(u[3] < lc.route_change_rate_per_s * DT_S, new_pref, g["preferred_lane"]),
    }


def states(seed, steps):
    """The states of one float64 simulation, step by step, with each step's key."""
    vehicles, state = scene.init_traffic(CFG, jax.random.key(seed), jnp.float64)
    step = jax.jit(scene.traffic_step, static_argnums=0)
    out = []
    for key in jax.random.split(jax.random.key(seed + 100), steps):
        out.append((state, key, step(CFG, vehicles, state, key)))
        state = out[-1][2]
    return vehicles, out


@pytest.fixture(scope="module")
def trajectories():
    return [states(seed, 80) for seed in range(4)]


def test_each_step_matches_the_loops(trajectories):
    for vehicles, steps in trajectories:
        for k, (state, key, got) in enumerate(steps):
            _, want = ref_step(CFG, vehicles, state, key)
            for name, value in want.items():
                np.testing.assert_allclose(np.asarray(getattr(got, name)), value, rtol=1e-12, atol=1e-12,
                                           err_msg=f"{name} at step {k}")


def test_the_steps_exercise_every_rule(trajectories):
    """Lane changes start (both ways) and end, drivers redraw speeds and routes: otherwise the
    comparison above would not see those rules (two starters at once: the test below)."""
    seen = {"left": 0, "right": 0, "ends": 0, "v0": 0, "route": 0}
    for vehicles, steps in trajectories:
        for state, key, got in steps:
            lane, target, new_target = (np.asarray(x) for x in (state.lane, state.target_lane, got.target_lane))
            starting = (new_target != target)
            seen["left"] += int(np.sum(starting & (new_target > lane)))
            seen["right"] += int(np.sum(starting & (new_target < lane)))
            seen["ends"] += int(np.sum(np.asarray(got.lane) != lane))
            seen["v0"] += int(np.sum(np.asarray(got.desired_speed_mps) != np.asarray(state.desired_speed_mps)))
            seen["route"] += int(np.sum(np.asarray(got.preferred_lane) != np.asarray(state.preferred_lane)))
    assert min(seen.values()) > 0, seen


def hand_state(vehicles, s, speed, preferred):
    """Lanes 0, 1, 2 hold vehicles 0-3, 4-7, 8-11, none changing or cooling down."""
    n = len(s)
    lane = jnp.asarray(np.repeat(np.arange(3), 4), jnp.int32)
    return scene.TrafficState(
        s_m=jnp.asarray(s), speed_mps=jnp.asarray(speed, float), lane=lane, target_lane=lane,
        since_change_s=jnp.full(n, 1e3), change_duration_s=jnp.full(n, 1.5),
        desired_speed_mps=vehicles.idm.desired_speed_mps, preferred_lane=jnp.asarray(preferred, jnp.int32))


def step_both(vehicles, state):
    """`traffic_step` checked against the loops; (next state, starters held back)."""
    key = jax.random.key(3)
    got = jax.jit(scene.traffic_step, static_argnums=0)(CFG, vehicles, state, key)
    info, want = ref_step(CFG, vehicles, state, key)
    for name, value in want.items():
        np.testing.assert_allclose(np.asarray(getattr(got, name)), value, rtol=1e-12, atol=1e-12, err_msg=name)
    return got, info["held"]


@pytest.mark.parametrize(("apart_m", "both_go"), [(10.0, False), (40.0, True)])
def test_two_close_starters_into_one_lane_only_the_lower_index_goes(apart_m, both_go):
    """Vehicle 0 (lane 0) and vehicle 8 (lane 2) both want lane 1 (their routes lead across it),
    which is empty near them; `apart_m` between their centres, against 12 m of conflict distance
    plus half their lengths."""
    vehicles, _ = scene.init_traffic(CFG, jax.random.key(0), jnp.float64)
    s = np.array([0.0, 0.3, 0.5, 0.75, 0.3, 0.45, 0.6, 0.75, 0.0, 0.25, 0.5, 0.75]) * float(vehicles.ring_length_m)
    s[8] = apart_m
    preferred = np.repeat(np.arange(3), 4)
    preferred[[0, 8]] = [2, 0]
    got, held = step_both(vehicles, hand_state(vehicles, s, np.full(12, 20.0), preferred))
    assert held == (0 if both_go else 1)
    target = np.asarray(got.target_lane)
    np.testing.assert_array_equal(target[[0, 8]], [1, 1] if both_go else [1, 2])
    assert np.sum(target != np.repeat(np.arange(3), 4)) == (2 if both_go else 1)


def test_a_start_flips_where_the_incentive_crosses_the_threshold_and_keep_right_bias():
    """The scene above 40 m apart: vehicle 0 heads left, vehicle 8 right. With a_th set 1e-6 either
    side of incentive - bias (left) or incentive + bias (right) each goes or stays: this pins both
    incentives and the keep-right bias in MOBIL's test."""
    vehicles, _ = scene.init_traffic(CFG, jax.random.key(0), jnp.float64)
    s = np.array([0.0, 0.3, 0.5, 0.75, 0.3, 0.45, 0.6, 0.75, 0.0, 0.25, 0.5, 0.75]) * float(vehicles.ring_length_m)
    s[8] = 40.0
    preferred = np.repeat(np.arange(3), 4)
    preferred[[0, 8]] = [2, 0]
    state = hand_state(vehicles, s, np.full(12, 20.0), preferred)
    key = jax.random.key(3)
    info, _ = ref_step(CFG, vehicles, state, key)
    bias = CFG.lane_change.keep_right_bias_mps2
    for vehicle, edge in ((0, info["incentive"][0, 2] - bias), (8, info["incentive"][8, 0] + bias)):
        for shift in (-1e-6, 1e-6):
            cfg = replace(CFG, lane_change=replace(CFG.lane_change, threshold_mps2=float(edge + shift)))
            got = jax.jit(scene.traffic_step, static_argnums=0)(cfg, vehicles, state, key)
            assert (int(got.target_lane[vehicle]) != int(state.lane[vehicle])) == (shift < 0), (vehicle, shift)


def test_blocked_in_the_middle_lane_with_both_sides_free_the_driver_keeps_right():
    """Vehicle 4 closes on slow vehicle 5 in lane 1; lanes 0 and 2 are empty beside them and the
    route is lane 1. All drivers and bodies are vehicle 0's, and lanes 0 and 2 hold the same
    places, so the two sides gain exactly the same: the keep-right bias picks the right one."""
    vehicles, _ = scene.init_traffic(CFG, jax.random.key(0), jnp.float64)
    same = lambda x: jnp.full_like(x, x[0]) if jnp.ndim(x) else x
    vehicles = jax.tree_util.tree_map(same, vehicles)
    s = np.array([0.5, 0.6, 0.7, 0.8, 0.0, 0.0, 0.5, 0.7, 0.5, 0.6, 0.7, 0.8]) * float(vehicles.ring_length_m)
    s[5] = 25.0
    speed = np.full(12, 20.0)
    speed[5] = 8.0
    got, held = step_both(vehicles, hand_state(vehicles, s, speed, np.repeat(np.arange(3), 4)))
    target = np.asarray(got.target_lane)
    assert target[4] == 0 and held == 0


def test_neighbour_tables_match_the_loops_with_a_vehicle_half_a_metre_ahead_in_the_next_lane():
    """Vehicle 4 (lane 1) has vehicle 0 (lane 0) 0.5 m ahead: 0 leads it in lane 0 and is not
    also its follower there; the follower is the nearest behind (vehicle 3, around the ring).
    Vehicle 8 (lane 2) is exactly abreast: both leader and follower there, 0 m away."""
    vehicles, _ = scene.init_traffic(CFG, jax.random.key(0), jnp.float64)
    ring = float(vehicles.ring_length_m)
    s = np.array([0.5, 0.2, 0.45, 0.7, 0.0, 0.3, 0.5, 0.7, 0.1, 0.35, 0.6, 0.85]) * ring
    s[[0, 8]] = 0.5, 0.0
    state = hand_state(vehicles, s, np.full(12, 20.0), np.repeat(np.arange(3), 4))
    got = jax.jit(_neighbours)(state, vehicles)
    leader, lead_d, follower, foll_d = neighbours(state, ring)
    np.testing.assert_array_equal(np.asarray(got[0]), np.where(np.equal(leader, None), 0, leader).astype(int))
    np.testing.assert_array_equal(np.asarray(got[3]), np.where(np.equal(follower, None), 0, follower).astype(int))
    np.testing.assert_allclose(np.asarray(got[1]), np.asarray(lead_d, float), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(got[4]), np.asarray(foll_d, float), rtol=1e-12)
    assert (leader[4][0], lead_d[4][0]) == (0, 0.5) and follower[4][0] == 3
    assert (leader[4][2], lead_d[4][2], follower[4][2], foll_d[4][2]) == (8, 0.0, 8, 0.0)


@pytest.mark.parametrize("gap_m", [0.5, 2.0, 2.1, 8.0, 30.0, 90.0, 1e4])
def test_equilibrium_speed_lies_within_v0_over_2_to_the_18_below_the_true_one(gap_m):
    p = scene.IDMParams(desired_speed_mps=31.0, time_headway_s=1.4, min_gap_m=2.0, max_accel_mps2=1.3,
                  comfort_decel_mps2=1.8, accel_exponent=3.5)
    got = float(_equilibrium_speed(jnp.asarray([gap_m]), jax.tree_util.tree_map(lambda x: jnp.asarray([x]), p))[0])
    want = steady_speed(gap_m, p)
    assert want - 31.0 * 2.0**-18 <= got <= want  # 18 halvings of [0, v0], the lower end kept
    if gap_m <= 2.0:
        assert got == 0.0  # no speed fits a gap under s0: standing
