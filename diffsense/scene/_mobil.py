"""MOBIL lane-change decision (Kesting, Treiber & Helbing 2007), for background traffic.

A driver c considers changing to a neighbouring lane; n is the new follower there and o the old
follower behind c now. With a_x the current IDM accelerations and a~_x those after the change:

- safety:    a~_n >= -b_safe              (the new follower need not brake harder than b_safe)
- incentive: a~_c - a_c + p (a~_n - a_n + a~_o - a_o) > a_th + bias

Units: accelerations [m/s2]. `bias_mps2` > 0 discourages the change (e.g. leaving the right lane
under a keep-right rule); negative encourages it.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class MOBILParams:
    """MOBIL parameters (Treiber & Kesting 2013, Sec. 14.3 typical values).

    Attributes:
        politeness: p, weight of the followers' advantage [-].
        threshold_mps2: a_th, minimum own advantage to change [m/s2].
        safe_decel_mps2: b_safe, maximum braking imposed on the new follower (positive) [m/s2].
        keep_right_bias_mps2: extra advantage needed to leave a lane to the left [m/s2].
    """

    politeness: Float[ArrayLike, ""] = 0.3
    threshold_mps2: Float[ArrayLike, ""] = 0.2
    safe_decel_mps2: Float[ArrayLike, ""] = 4.0
    keep_right_bias_mps2: Float[ArrayLike, ""] = 0.2


def mobil_is_safe(new_follower_accel_after: Float[ArrayLike, "*V"], p: MOBILParams) -> Bool[Array, "*V"]:
    """The safety criterion: the new follower would brake no harder than b_safe."""
    return jnp.asarray(new_follower_accel_after) >= -p.safe_decel_mps2


def mobil_incentive_mps2(
    own_accel: Float[ArrayLike, "*V"],
    own_accel_after: Float[ArrayLike, "*V"],
    new_follower_accel: Float[ArrayLike, "*V"],
    new_follower_accel_after: Float[ArrayLike, "*V"],
    old_follower_accel: Float[ArrayLike, "*V"],
    old_follower_accel_after: Float[ArrayLike, "*V"],
    p: MOBILParams,
) -> Float[Array, "*V"]:
    """Own advantage plus the politeness-weighted advantage of both followers [m/s2]."""
    own = own_accel_after - own_accel
    others = (new_follower_accel_after - new_follower_accel) + (old_follower_accel_after - old_follower_accel)
    return own + p.politeness * others


def mobil_wants_change(
    incentive_mps2: Float[ArrayLike, "*V"],
    new_follower_accel_after: Float[ArrayLike, "*V"],
    to_left: Bool[ArrayLike, "*V"],
    p: MOBILParams,
) -> Bool[Array, "*V"]:
    """True where a change is both safe and worth it (keep-right bias applied to left changes)."""
    bias = jnp.where(to_left, p.keep_right_bias_mps2, -p.keep_right_bias_mps2)
    return mobil_is_safe(new_follower_accel_after, p) & (incentive_mps2 > p.threshold_mps2 + bias)
