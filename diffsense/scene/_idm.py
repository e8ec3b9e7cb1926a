"""Intelligent Driver Model (Treiber, Hennecke & Helbing 2000): longitudinal acceleration.

    a = a_max * [1 - (v / v0)^delta - (s* / s)^2],
    s* = s0 + max(0, v T + v dv / (2 sqrt(a_max b))),   dv = v - v_lead (closing speed).

Units: speeds [m/s], gaps [m] bumper to bumper, accelerations [m/s2].
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

# A free road is a leader this far ahead: (s*/s)^2 is then negligible for any highway speed.
FREE_ROAD_GAP_M = 1e4
# Gaps are floored here before dividing, so a touching (or overlapping) pair brakes hard and finitely.
_MIN_GAP_M = 0.05


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class IDMParams:
    """IDM parameters (scalars or per-vehicle arrays [V]).

    Defaults are Treiber & Kesting's (Traffic Flow Dynamics, 2013, Table 11.2) highway values,
    with the desired speed left to the caller.

    Attributes:
        desired_speed_mps: v0, the free-road speed [m/s].
        time_headway_s: T, the desired time gap [s].
        min_gap_m: s0, the standstill gap [m].
        max_accel_mps2: a_max, the maximum acceleration [m/s2].
        comfort_decel_mps2: b, the comfortable deceleration (positive) [m/s2].
        accel_exponent: delta, the free-road exponent [-].
    """

    desired_speed_mps: Float[ArrayLike, "*V"] = 33.3
    time_headway_s: Float[ArrayLike, "*V"] = 1.5
    min_gap_m: Float[ArrayLike, "*V"] = 2.0
    max_accel_mps2: Float[ArrayLike, "*V"] = 1.0
    comfort_decel_mps2: Float[ArrayLike, "*V"] = 1.5
    accel_exponent: Float[ArrayLike, "*V"] = 4.0


def desired_gap_m(
    speed_mps: Float[ArrayLike, "*V"], lead_speed_mps: Float[ArrayLike, "*V"], p: IDMParams
) -> Float[Array, "*V"]:
    """s*: the gap the driver wants at this speed and closing speed [m]."""
    closing_mps = speed_mps - lead_speed_mps
    dynamic = speed_mps * p.time_headway_s + speed_mps * closing_mps / (
        2.0 * jnp.sqrt(p.max_accel_mps2 * p.comfort_decel_mps2)
    )
    return p.min_gap_m + jnp.maximum(dynamic, 0.0)


def idm_acceleration(
    speed_mps: Float[ArrayLike, "*V"],
    gap_m: Float[ArrayLike, "*V"],
    lead_speed_mps: Float[ArrayLike, "*V"],
    p: IDMParams,
) -> Float[Array, "*V"]:
    """IDM acceleration [m/s2] given own speed, bumper-to-bumper gap and the leader's speed.

    For a free road pass `gap_m = FREE_ROAD_GAP_M` and any leader speed.
    """
    speed_mps = jnp.maximum(jnp.asarray(speed_mps), 0.0)
    free_road = 1.0 - (speed_mps / p.desired_speed_mps) ** p.accel_exponent
    gap = jnp.maximum(gap_m, _MIN_GAP_M)
    interaction = (desired_gap_m(speed_mps, lead_speed_mps, p) / gap) ** 2
    return p.max_accel_mps2 * (free_road - interaction)


def equilibrium_gap_m(speed_mps: Float[ArrayLike, "*V"], p: IDMParams) -> Float[Array, "*V"]:
    """The steady-state gap of a follower behind a leader at the same constant speed [m].

    From a = 0 with dv = 0: s_e = (s0 + v T) / sqrt(1 - (v / v0)^delta). Useful to place vehicles
    so that a scenario starts in equilibrium. Speeds at or above v0 get an infinite gap.
    """
    speed_mps = jnp.asarray(speed_mps)
    free = 1.0 - (speed_mps / p.desired_speed_mps) ** p.accel_exponent
    safe_free = jnp.where(free > 0.0, free, 1.0)
    gap = (p.min_gap_m + speed_mps * p.time_headway_s) / jnp.sqrt(safe_free)
    return jnp.where(free > 0.0, gap, jnp.inf)
