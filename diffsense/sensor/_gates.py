"""Detection gates: soft (logistic of margin / tau, multiplied in log space) or hard (indicators).

A sensor's detection probability is a product of gates, each a signed margin in physical units
(deg, m, dB, px) that is >= 0 where the condition holds. Soft mode forms
`exp(sum log_sigmoid(margin / tau))`: never a product of tiny numbers, finite gradients for any
tau > 0. Hard mode is the product of the indicators `margin >= 0` themselves (no tiny tau).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

Mode = Literal["soft", "hard"]
MODES: tuple[str, ...] = ("soft", "hard")


def check_mode(mode: str) -> Mode:
    from diffsense.errors import InputError

    if mode not in MODES:
        raise InputError(f"unknown detection mode {mode!r} (known: soft, hard)")
    return mode  # type: ignore[return-value]


def p_from_gates(
    gates: Sequence[tuple[Float[Array, "..."], float | Float[Array, ""]]], mode: Mode
) -> Float[Array, "..."]:
    """Detection probability from `(margin, tau)` pairs: soft logistic product or hard AND."""
    if mode == "hard":
        p = 1.0
        for margin, _ in gates:
            p = p * (margin >= 0).astype(margin.dtype)
        return p
    log_p = sum(jax.nn.log_sigmoid(margin / tau) for margin, tau in gates)
    return jnp.exp(log_p)


def soft_ramp(x: Float[Array, "..."], cap: Float[Array, "..."], tau, mode: Mode):
    """clip(x, 0, cap) (hard) or its softplus smoothing of width tau (soft); cap >= 0."""
    if mode == "hard":
        return jnp.clip(x, 0.0, cap)
    return tau * (jax.nn.softplus(x / tau) - jax.nn.softplus((x - cap) / tau))


def soft_less(a: Float[Array, "..."], b: Float[Array, "..."], tau, mode: Mode):
    """Indicator a < b (hard) or sigmoid((b - a) / tau) (soft)."""
    if mode == "hard":
        return (a < b).astype(jnp.result_type(a, b))
    return jax.nn.sigmoid((b - a) / tau)
