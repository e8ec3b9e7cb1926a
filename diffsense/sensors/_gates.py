"""Detection gates: soft (logistic of margin / tau, multiplied in log space) or hard (indicators).

A sensor's detection probability is a product of gates, each a signed margin in physical units
(deg, m, dB, px) that is >= 0 where the condition holds. Soft mode forms
`exp(sum log_sigmoid(margin / tau))`: never a product of tiny numbers, finite gradients for any
tau > 0. Hard mode is the product of the indicators `margin >= 0` themselves (no tiny tau).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from diffsense.runtime import InputError

Mode = Literal["soft", "hard"]
MODES: tuple[str, ...] = ("soft", "hard")

# exp() is never taken of anything below these: results in float32's subnormal range (below
# ~1e-38, e^-87) make x86 CPUs take a slow path, tens of times slower per element. The
# corrections cut off are below e^-30 ~ 1e-13 (softplus tail) and p below e^-80 ~ 2e-35.
_TAIL_CLIP = 30.0
_LOG_P_MIN = -80.0


def softplus(z: Float[Array, "..."]) -> Float[Array, "..."]:
    """log(1 + e^z), stable, never computing a subnormal exponential."""
    return jnp.maximum(z, 0.0) + jnp.log1p(jnp.exp(-jnp.minimum(jnp.abs(z), _TAIL_CLIP)))


def log_sigmoid(z: Float[Array, "..."]) -> Float[Array, "..."]:
    """log(sigmoid(z)) = -softplus(-z)."""
    return -softplus(-z)


def exp_log_p(log_p: Float[Array, "..."]) -> Float[Array, "..."]:
    """A probability from its log, floored at e^-80 (no subnormals)."""
    return jnp.exp(jnp.maximum(log_p, _LOG_P_MIN))


def check_mode(mode: str) -> Mode:
    if mode not in MODES:
        raise InputError(f"unknown detection mode {mode!r} (known: soft, hard)")
    return mode  # type: ignore[return-value]


def check_temperature(temperature):
    """Refuse a concrete temperature that is not a positive finite number (traced: unchecked)."""
    try:
        value = float(temperature)
    except (TypeError, ValueError, jax.errors.ConcretizationTypeError):
        return temperature  # traced, or an array: the caller's (solver's) business
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"temperature must be a positive number, got {value:g}")
    return temperature


def p_from_gates(
    gates: Sequence[tuple[Float[Array, "..."], float | Float[Array, ""]]], mode: Mode
) -> Float[Array, "..."]:
    """Detection probability from `(margin, tau)` pairs: soft logistic product or hard AND.

    A probabilistic detection law (`_laws.py`) gives its log-probability instead of gates; it
    is the probability of the physical event in either mode.
    """
    log_p = getattr(gates, "log_p", None)
    if log_p is not None:
        return exp_log_p(log_p)
    if mode == "hard":
        p = 1.0
        for margin, _ in gates:
            p = p * (margin >= 0).astype(margin.dtype)
        return p
    return exp_log_p(sum(log_sigmoid(margin / tau) for margin, tau in gates))


def soft_ramp(x: Float[Array, "..."], cap: Float[Array, "..."], tau, mode: Mode):
    """clip(x, 0, cap) (hard) or a smooth ramp from 0 to cap with corners of width tau (soft).

    The corners are the algebraic smooth ReLU 0.5 (x + sqrt(x^2 + tau^2)): within tau / 2 of the
    clip everywhere, and two square roots per pair instead of four transcendentals (the
    occlusion pairs are the sensor's largest arrays).
    """
    if mode == "hard":
        return jnp.clip(x, 0.0, cap)
    def relu(z):
        return 0.5 * (z + jnp.sqrt(z * z + tau * tau))
    return relu(x) - relu(x - cap)


def soft_less(a: Float[Array, "..."], b: Float[Array, "..."], tau, mode: Mode):
    """Indicator a < b (hard) or sigmoid((b - a) / tau) (soft, as 0.5 + 0.5 tanh: no subnormals)."""
    if mode == "hard":
        return (a < b).astype(jnp.result_type(a, b))
    return 0.5 + 0.5 * jnp.tanh(0.5 * (b - a) / tau)
