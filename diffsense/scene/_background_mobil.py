"""MOBIL lane changes of a scene's background vehicles, decided once per simulation step.

A background vehicle that is not changing lane asks MOBIL (diffsense.scene._mobil) about the lane
on each side: its new leader and follower there, and its old follower, are the nearest vehicles
ahead and behind that occupy that lane now or are heading into it. A change also needs a
bumper gap of at least the IDM standstill gap s0 to both new neighbours. At most one vehicle per
scene starts a change in a step (the one with the largest incentive), so two vehicles never
start into the same gap at once; the next step sees the first one heading there.
Scripted vehicles (ego, target and the other roles) never ask.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from diffsense.scene._idm import FREE_ROAD_GAP_M, IDMParams, idm_acceleration
from diffsense.scene._mobil import MOBILParams, mobil_incentive_mps2, mobil_wants_change


def _nearest(s, length, member, ahead: bool):
    """Per vehicle c (rows), the nearest member j (columns) ahead of (or behind) it: index, gap.

    A member exactly abreast counts as ahead (with a negative gap), so it is never overlooked."""
    ds = s[None, :] - s[:, None]
    side = ds >= 0 if ahead else ds < 0
    gap = jnp.abs(ds) - 0.5 * (length[None, :] + length[:, None])
    gap = jnp.where(member & side, gap, FREE_ROAD_GAP_M)
    j = jnp.argmin(gap, axis=-1)
    return j, jnp.take_along_axis(gap, j[:, None], -1)[:, 0]


def _idm_of(p: IDMParams, j: Int[Array, " V"]) -> IDMParams:
    return IDMParams(*(jnp.broadcast_to(x, j.shape) if jnp.ndim(x) == 0 else x[j] for x in (
        p.desired_speed_mps, p.time_headway_s, p.min_gap_m, p.max_accel_mps2, p.comfort_decel_mps2, p.accel_exponent)))


def lane_change_starts(
    s_m: Float[Array, " V"], d_m: Float[Array, " V"], lane_centre_m: Float[Array, " V"],
    speed_mps: Float[Array, " V"], accel_mps2: Float[Array, " V"], length_m: Float[Array, " V"],
    idm: IDMParams, free: Bool[Array, " V"], lane_width_m: Float[Array, ""], num_lanes: Int[Array, ""],
    p: MOBILParams,
) -> tuple[Bool[Array, " V"], Float[Array, " V"]]:
    """Which vehicle starts a lane change now (at most one) and the lane centre it heads for [m].

    `lane_centre_m` is each vehicle's lane (or the lane it is heading into); `free` marks the
    vehicles allowed to decide (background, not changing); `accel_mps2` their IDM accelerations now.
    """
    v = s_m.shape[-1]
    others = ~jnp.eye(v, dtype=bool)
    in_lane = lambda centre: others & (  # noqa: E731  (j occupies or heads for c's lane `centre`)
        (jnp.abs(d_m[None, :] - centre[:, None]) < 0.5 * lane_width_m)
        | (jnp.abs(lane_centre_m[None, :] - centre[:, None]) < 0.5 * lane_width_m))
    own = in_lane(lane_centre_m)
    leader, leader_gap = _nearest(s_m, length_m, own, ahead=True)
    has_leader = leader_gap < FREE_ROAD_GAP_M
    old_f, old_f_gap = _nearest(s_m, length_m, own, ahead=False)
    has_old_f = old_f_gap < FREE_ROAD_GAP_M
    # The old follower after the change follows c's leader (bumper gap from its front to that rear).
    old_f_gap_after = jnp.where(has_leader, s_m[leader] - s_m[old_f] - 0.5 * (length_m[leader] + length_m[old_f]),
                                FREE_ROAD_GAP_M)
    old_f_after = idm_acceleration(speed_mps[old_f], old_f_gap_after, speed_mps[leader], _idm_of(idm, old_f))
    lane = jnp.floor(lane_centre_m / lane_width_m)
    best, best_to = jnp.full((v,), -jnp.inf, s_m.dtype), lane_centre_m
    for side in (1.0, -1.0):  # left, right
        centre = lane_centre_m + side * lane_width_m
        there = in_lane(centre)
        new_l, new_l_gap = _nearest(s_m, length_m, there, ahead=True)
        new_f, new_f_gap = _nearest(s_m, length_m, there, ahead=False)
        has_new_f = new_f_gap < FREE_ROAD_GAP_M
        own_after = idm_acceleration(speed_mps, new_l_gap, speed_mps[new_l], idm)
        new_f_after = idm_acceleration(speed_mps[new_f], new_f_gap, speed_mps, _idm_of(idm, new_f))
        new_f_after = jnp.where(has_new_f, new_f_after, 0.0)
        new_f_now = jnp.where(has_new_f, accel_mps2[new_f], 0.0)
        incentive = mobil_incentive_mps2(
            accel_mps2, own_after, new_f_now, new_f_after,
            jnp.where(has_old_f, accel_mps2[old_f], 0.0), jnp.where(has_old_f, old_f_after, 0.0), p)
        room = (new_l_gap > idm.min_gap_m) & (new_f_gap > idm.min_gap_m)
        exists = (lane + side >= 0) & (lane + side <= num_lanes - 1)
        wants = mobil_wants_change(incentive, new_f_after, side > 0, p) & room & exists & free
        score = jnp.where(wants, incentive, -jnp.inf)
        better = score > best
        best, best_to = jnp.where(better, score, best), jnp.where(better, centre, best_to)
    starts = (jnp.arange(v) == jnp.argmax(best)) & jnp.isfinite(best)
    return starts, best_to
