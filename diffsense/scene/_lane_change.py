"""Lateral lane-change profile: a quintic (minimum-jerk) blend between two lateral offsets.

    d(t) = d0 + (d1 - d0) * (10 u^3 - 15 u^4 + 6 u^5),   u = clip((t - t0) / duration, 0, 1)

Lateral speed and acceleration are zero at both ends, so the manoeuvre joins straight driving
smoothly. Units: t [s], d [m].
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float


def quintic_progress(t_s: Float[ArrayLike, "*T"], start_s: Float[ArrayLike, ""], duration_s: Float[ArrayLike, ""]) -> Float[Array, "*T"]:
    """Fraction of the lateral displacement done at time t, in [0, 1] [-]."""
    u = jnp.clip((jnp.asarray(t_s) - start_s) / duration_s, 0.0, 1.0)
    return u**3 * (10.0 - 15.0 * u + 6.0 * u**2)


def quintic_lateral_offset_m(
    t_s: Float[ArrayLike, "*T"],
    start_s: Float[ArrayLike, ""],
    duration_s: Float[ArrayLike, ""],
    d_from_m: Float[ArrayLike, ""],
    d_to_m: Float[ArrayLike, ""],
) -> Float[Array, "*T"]:
    """Lateral offset d(t) of a lane change from `d_from_m` to `d_to_m` [m]."""
    return d_from_m + (d_to_m - d_from_m) * quintic_progress(t_s, start_s, duration_s)


def quintic_lateral_speed_mps(
    t_s: Float[ArrayLike, "*T"],
    start_s: Float[ArrayLike, ""],
    duration_s: Float[ArrayLike, ""],
    d_from_m: Float[ArrayLike, ""],
    d_to_m: Float[ArrayLike, ""],
) -> Float[Array, "*T"]:
    """Lateral speed dd/dt of the same lane change [m/s] (zero before and after it)."""
    u = jnp.clip((jnp.asarray(t_s) - start_s) / duration_s, 0.0, 1.0)
    return (d_to_m - d_from_m) * 30.0 * u**2 * (1.0 - u) ** 2 / duration_s
