"""Training traffic: IDM + MOBIL vehicles on a straight multi-lane ring road, at 10 Hz.

The road is straight and closed into a ring of length L, so that the density of a simulation
stays what was drawn: L = vehicles_per_lane / density. Lane 0 is the rightmost; the lateral
offset d is measured from the right road edge, left positive, so lane k's centre is at
d = (k + 1/2) * lane_width. Arc length s is kept unwrapped (it only grows); distances on the
ring are taken modulo L.

Each step (dt = 0.1 s):
- every vehicle finds, in the lanes right of, at and left of its own, the nearest vehicle ahead
  (leader) and behind (follower); a vehicle that is changing lanes occupies both lanes;
- longitudinal: IDM towards the leader of every lane it occupies, the most cautious one applies
  (diffsense.scene._idm); ballistic update that never reverses;
- lateral: a vehicle not changing lanes and out of its cool-down asks MOBIL
  (diffsense.scene._mobil) about both neighbouring lanes and starts a quintic lane change
  (diffsense.scene._lane_change) of a duration drawn from the config; two vehicles that would
  start into a common lane close to each other in the same step are resolved by index;
- drivers redraw their desired speed at a small rate, which makes braking waves, and their
  preferred lane (a route towards an exit or away from a merge, as on US-101), which adds a
  bonus to MOBIL's incentive towards it.

`simulate_traffic` runs one simulation; vmap it over keys for independent simulations. The
datatypes and the initial placement are in diffsense.scene._traffic_state.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int, PRNGKeyArray

from diffsense import runtime
from diffsense.scene._idm import FREE_ROAD_GAP_M, IDMParams, idm_acceleration
from diffsense.scene._mobil import MOBILParams, mobil_incentive_mps2, mobil_wants_change
from diffsense.scene._traffic_config import TrafficConfig
from diffsense.scene._traffic_state import (
    DT_S,
    TrafficState,
    TrafficTrajectories,
    TrafficVehicles,
    init_traffic,
    lateral_offset_m,
    num_steps,
)

# Relative lanes of the neighbour tables: right of, at, left of a vehicle's (origin) lane.
_RIGHT, _OWN, _LEFT = 0, 1, 2


def _take(x: Array, index: Int[Array, "..."]) -> Array:
    """x[index] for a per-vehicle array x [V] (index may have any shape)."""
    return x[index]


def _idm_of(p: IDMParams, index: Int[Array, "..."]) -> IDMParams:
    return jax.tree_util.tree_map(lambda a: _take(a, index), p)


def _neighbours(state: TrafficState, vehicles: TrafficVehicles):
    """Leader and follower of every vehicle in the lanes right of, at and left of its own.

    Returns (leader, leader_dist, has_leader, follower, follower_dist, has_follower), each [V, 3],
    and the [V, V] forward distances; distances are centre to centre along the ring [m].
    """
    s, ring = state.s_m, vehicles.ring_length_m
    num_v = s.shape[0]
    ahead = _ahead_m(s, ring)  # [i, j]: how far j is ahead of i
    behind = jnp.where(ahead > 0.0, ring - ahead, 0.0)
    rel = jnp.arange(3) - 1  # right, own, left
    lane_of_i = state.lane[:, None, None] + rel[None, :, None]  # [i, r, 1]
    occupies = (state.lane[None, None, :] == lane_of_i) | (state.target_lane[None, None, :] == lane_of_i)
    occupies &= ~jnp.eye(num_v, dtype=bool)[:, None, :]  # [i, r, j]: the minor axis is reduced
    big = jnp.asarray(jnp.inf, s.dtype)
    ahead_r = jnp.where(occupies, ahead[:, None, :], big)
    behind_r = jnp.where(occupies, behind[:, None, :], big)
    leader = jnp.argmin(ahead_r, axis=2)
    follower = jnp.argmin(behind_r, axis=2)
    leader_dist = jnp.take_along_axis(ahead_r, leader[:, :, None], axis=2)[:, :, 0]
    follower_dist = jnp.take_along_axis(behind_r, follower[:, :, None], axis=2)[:, :, 0]
    return leader, leader_dist, jnp.isfinite(leader_dist), follower, follower_dist, jnp.isfinite(follower_dist), ahead


def _ahead_m(s: Float[Array, "V"], ring: Float[Array, ""]) -> Float[Array, "V V"]:
    """[i, j]: distance from i forward to j along the ring, in [0, ring) [m]."""
    return jnp.mod(s[None, :] - s[:, None], ring)


def _idm_towards(speed, own_len, p: IDMParams, lead_dist, lead_len, lead_speed, has_lead):
    """IDM acceleration towards a (maybe absent) leader at centre distance `lead_dist` [m/s2].

    A driver above its desired speed (after picking a lower one) slows down at no more than its
    comfortable deceleration b: plain IDM would brake at a_max (v/v0)^4, over 10 m/s2 at twice
    v0 (the reason for Treiber & Kesting's IIDM). Braking for a leader is untouched.
    """
    gap = jnp.where(has_lead, lead_dist - 0.5 * (own_len + lead_len), FREE_ROAD_GAP_M)
    accel = idm_acceleration(speed, gap, jnp.where(has_lead, lead_speed, speed), p)
    free_road = p.max_accel_mps2 * (1.0 - (speed / p.desired_speed_mps) ** p.accel_exponent)
    return accel + jnp.maximum(-p.comfort_decel_mps2 - free_road, 0.0)


def _lane_change_starts(cfg: TrafficConfig, vehicles: TrafficVehicles, state: TrafficState, idm, accel, accel_r,
                        neighbours) -> tuple[Array, Array]:
    """Which vehicles start a lane change this step, and every vehicle's target lane [V] (MOBIL
    per side, then two close starters whose lanes would overlap resolved to the lower index)."""
    lc = cfg.lane_change
    num_v = state.s_m.shape[0]
    v, length = state.speed_mps, vehicles.length_m
    leader, lead_dist, has_lead, follower, foll_dist, has_foll, ahead = neighbours
    changing = state.target_lane != state.lane
    # Lateral decision (MOBIL) for vehicles in a lane, out of their cool-down.
    ready = ~changing & (state.since_change_s >= state.change_duration_s + lc.cooldown_s)
    old_f, has_old_f = follower[:, _OWN], has_foll[:, _OWN]
    own_leader, has_own_leader = leader[:, _OWN], has_lead[:, _OWN]
    # The old follower's leader once we are gone: ours (unless that is itself, on a short ring).
    o_has_new_lead = has_own_leader & has_old_f & (own_leader != old_f)
    o_accel_after = _idm_towards(
        v[old_f], length[old_f], _idm_of(idm, old_f), foll_dist[:, _OWN] + lead_dist[:, _OWN],
        length[own_leader], v[own_leader], o_has_new_lead,
    )
    o_gain = jnp.where(has_old_f, o_accel_after - accel[old_f], 0.0)
    mobil = MOBILParams(
        politeness=vehicles.politeness, threshold_mps2=lc.threshold_mps2,
        safe_decel_mps2=lc.safe_decel_mps2, keep_right_bias_mps2=lc.keep_right_bias_mps2,
    )

    def consider(r: int):
        new_f, has_new_f = follower[:, r], has_foll[:, r]
        n_accel_after = _idm_towards(v[new_f], length[new_f], _idm_of(idm, new_f), foll_dist[:, r], length, v, has_new_f)
        n_accel_after = jnp.where(has_new_f, n_accel_after, 0.0)
        n_accel = jnp.where(has_new_f, accel[new_f], 0.0)
        incentive = mobil_incentive_mps2(accel, accel_r[:, r], n_accel, n_accel_after, 0.0, o_gain, mobil)
        lead_gap = jnp.where(has_lead[:, r], lead_dist[:, r] - 0.5 * (length + length[leader[:, r]]), jnp.inf)
        foll_gap = jnp.where(has_new_f, foll_dist[:, r] - 0.5 * (length + length[new_f]), jnp.inf)
        lane_exists = (state.lane + r - 1 >= 0) & (state.lane + r - 1 < cfg.road.num_lanes)
        # Route: a bonus for moving towards the preferred lane, a malus for moving away.
        towards = jnp.sign(state.preferred_lane - state.lane) == r - 1
        incentive += jnp.where(towards, cfg.lane_change.route_bias_mps2, -cfg.lane_change.route_bias_mps2)
        wants = mobil_wants_change(incentive, n_accel_after, r == _LEFT, mobil)
        wants &= ready & lane_exists & (lead_gap > lc.min_gap_m) & (foll_gap > lc.min_gap_m)
        bias = lc.keep_right_bias_mps2 if r == _LEFT else -lc.keep_right_bias_mps2
        return wants, incentive - bias

    want_right, score_right = consider(_RIGHT)
    want_left, score_left = consider(_LEFT)
    go_left = want_left & (~want_right | (score_left > score_right))
    starts = want_left | want_right
    new_target = jnp.where(starts, state.lane + jnp.where(go_left, 1, -1), state.target_lane)

    # Two starters whose lanes would overlap and that are close: only the lower index goes.
    separation = jnp.minimum(ahead, vehicles.ring_length_m - ahead)
    close = separation < 0.5 * (length[:, None] + length[None, :]) + lc.conflict_distance_m
    lo_i = jnp.minimum(state.lane, new_target)
    hi_i = jnp.maximum(state.lane, new_target)
    share = (lo_i[:, None] <= hi_i[None, :]) & (lo_i[None, :] <= hi_i[:, None])
    blocked = jnp.any(starts[None, :] & close & share & (jnp.arange(num_v)[None, :] < jnp.arange(num_v)[:, None]), axis=1)
    starts &= ~blocked
    new_target = jnp.where(starts, new_target, state.target_lane)
    return starts, new_target


def traffic_step(
    cfg: TrafficConfig, vehicles: TrafficVehicles, state: TrafficState, key: PRNGKeyArray
) -> TrafficState:
    """Advance one simulation by one 0.1 s step."""
    lc = cfg.lane_change
    dtype = state.s_m.dtype
    num_v = state.s_m.shape[0]
    v, length = state.speed_mps, vehicles.length_m
    idm = dataclasses.replace(vehicles.idm, desired_speed_mps=state.desired_speed_mps)
    neighbours = _neighbours(state, vehicles)
    leader, lead_dist, has_lead = neighbours[:3]

    # Longitudinal: IDM towards the leader of each relative lane; a vehicle obeys every lane it occupies.
    idm_r = jax.tree_util.tree_map(lambda a: a[:, None], idm)
    accel_r = _idm_towards(v[:, None], length[:, None], idm_r, lead_dist, length[leader], v[leader], has_lead)
    to_r = jnp.clip(state.target_lane - state.lane + 1, 0, 2)
    accel = jnp.minimum(accel_r[:, _OWN], jnp.take_along_axis(accel_r, to_r[:, None], axis=1)[:, 0])

    starts, new_target = _lane_change_starts(cfg, vehicles, state, idm, accel, accel_r, neighbours)

    u = runtime.uniform(key, (5, num_v), dtype)
    duration = jnp.where(starts, lc.duration_s[0] + u[0] * (lc.duration_s[1] - lc.duration_s[0]), state.change_duration_s)
    since = jnp.where(starts, 0.0, state.since_change_s) + DT_S
    done = (new_target != state.lane) & (since >= duration)
    lane = jnp.where(done, new_target, state.lane)

    # Ballistic longitudinal update that stops at zero speed instead of reversing.
    v_new = v + accel * DT_S
    stops = v_new < 0.0
    safe_accel = jnp.where(stops, jnp.minimum(accel, -1e-3), accel)
    ds = jnp.where(stops, -0.5 * v * v / safe_accel, v * DT_S + 0.5 * accel * DT_S * DT_S)

    # Drivers occasionally pick a new desired speed (a new mood, a speed limit sign).
    lo, hi = cfg.traffic.speed_change_factor
    redraw = u[1] < cfg.traffic.speed_change_rate_per_s * DT_S
    new_v0 = jnp.minimum(vehicles.mean_desired_speed_mps * (lo + (hi - lo) * u[2]), vehicles.max_desired_speed_mps)
    new_preferred = jnp.minimum((u[4] * cfg.road.num_lanes).astype(jnp.int32), cfg.road.num_lanes - 1)
    return TrafficState(
        s_m=state.s_m + ds,
        speed_mps=jnp.maximum(v_new, 0.0),
        lane=lane,
        target_lane=new_target,
        since_change_s=since.astype(dtype),
        change_duration_s=duration.astype(dtype),
        desired_speed_mps=jnp.where(redraw, new_v0, state.desired_speed_mps),
        preferred_lane=jnp.where(u[3] < lc.route_change_rate_per_s * DT_S, new_preferred, state.preferred_lane),
    )


def simulate_traffic(cfg: TrafficConfig, key: PRNGKeyArray, dtype=jnp.float32) -> TrafficTrajectories:
    """One simulation of `cfg`: warm-up, then the recorded frames at 10 Hz.

    `cfg` is static (hashable); vmap over `key` for independent simulations, e.g.
    `jax.jit(jax.vmap(simulate_traffic, (None, 0)), static_argnums=0)`.
    """
    init_key, run_key = jax.random.split(key)
    vehicles, state = init_traffic(cfg, init_key, dtype)
    warmup, recorded = num_steps(cfg)
    lane_width = cfg.road.lane_width_m

    def step(state, k):
        frame = (state.s_m, lateral_offset_m(state, lane_width), state.speed_mps, state.lane, state.target_lane)
        return traffic_step(cfg, vehicles, state, k), frame

    # One scan over warm-up and recording (two scans would compile the step twice); the warm-up
    # frames are dropped.
    _, frames = jax.lax.scan(step, state, jax.random.split(run_key, warmup + recorded))
    s, d, speed, lane, target = (f[warmup:] for f in frames)
    return TrafficTrajectories(s_m=s, d_m=d, speed_mps=speed, lane=lane, target_lane=target, vehicles=vehicles)
