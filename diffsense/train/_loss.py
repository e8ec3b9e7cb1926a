"""The reference's training losses, written to be finite everywhere.

All on raw decoder outputs r [B, 25, 5] (before the output activation) in the model frame:
mu = r[..., :2]; 1/sigma = exp(r[..., 2:4]); rho = tanh(r[..., 4]).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

_LOG_2PI = math.log(2 * math.pi)  # the reference's constant 1.8379
_RHO_RAW_MAX = 15.0  # |atanh(rho)| cap: 1 - rho^2 >= 4e-13, far beyond anything the data needs
_LOG_INV_SIGMA_MAX = 20.0  # |log(1/sigma)| cap: sigma in [2e-9, 5e8] ft keeps every term finite


def mse(raw: Float[Array, "B T 5"], fut: Float[Array, "B T 2"]) -> Float[Array, ""]:
    """maskedMSE: mean over points of the squared distance between mean and truth."""
    return jnp.mean(jnp.sum((raw[..., :2] - fut) ** 2, axis=-1))


def _log_cosh(z):
    a = jnp.abs(z)
    return a + jnp.log1p(jnp.exp(-2.0 * a)) - math.log(2.0)


def nll(raw: Float[Array, "B T 5"], fut: Float[Array, "B T 2"]) -> Float[Array, ""]:
    """maskedNLL: bivariate Gaussian negative log-likelihood per point, averaged.

    The reference computes ohr = (1 - rho^2)^-1/2 from tanh(z), which is inf when tanh rounds
    to +-1; here log(ohr) = log cosh(z) and ohr^2 = exp(2 log cosh z). z and the log inverse
    sigmas are capped (clip: no gradient beyond the cap, where training never goes).
    """
    z = jnp.clip(raw[..., 4], -_RHO_RAW_MAX, _RHO_RAW_MAX)
    log_sx = jnp.clip(raw[..., 2], -_LOG_INV_SIGMA_MAX, _LOG_INV_SIGMA_MAX)
    log_sy = jnp.clip(raw[..., 3], -_LOG_INV_SIGMA_MAX, _LOG_INV_SIGMA_MAX)
    rho = jnp.tanh(z)
    log_ohr = _log_cosh(z)
    sx, sy = jnp.exp(log_sx), jnp.exp(log_sy)
    dx, dy = fut[..., 0] - raw[..., 0], fut[..., 1] - raw[..., 1]
    quad = (sx * dx) ** 2 + (sy * dy) ** 2 - 2.0 * rho * sx * sy * dx * dy
    per_point = 0.5 * jnp.exp(2.0 * log_ohr) * quad - (log_sx + log_sy + log_ohr) + _LOG_2PI
    return jnp.mean(per_point)


def class_bce(logits: Float[Array, "B C"], label: Int[Array, "B"]) -> Float[Array, ""]:
    """torch.nn.BCELoss of softmax probabilities against one-hot labels (mean over B x C).

    log p and log(1 - p) both come from log-sum-exp of the logits, so p -> 0 or 1 stays finite.
    """
    onehot = jax.nn.one_hot(label, logits.shape[-1], dtype=logits.dtype)
    log_total = jax.nn.logsumexp(logits, axis=-1, keepdims=True)
    log_p = logits - log_total
    others = jnp.where(jnp.eye(logits.shape[-1], dtype=bool)[None], -jnp.inf, logits[:, None, :])
    log_not_p = jax.nn.logsumexp(others, axis=-1) - log_total
    return -jnp.mean(onehot * log_p + (1.0 - onehot) * log_not_p)
