"""The reference objective E_ref(r): the expectation of the hard objective over detection draws.

Where detection is a random event (a probabilistic `[detection] law`, `diffsense.sensors._laws`),
the sensor gives for every (frame, vehicle) the probability p of the physical detection event.
E_ref^2 is the mean over K draws of the hard objective (Eq. 12's E^2, or J of "tracked"), each
draw detecting (frame, vehicle) when u < p for a uniform u:

    E_ref(r)^2 = (1/K) sum_k E_hard^2(r; detections 1[u_k < p(r)])                       [m^2]

The uniforms come from each variant's measurement-noise key folded with a fixed stream number
and the draw's index: common random numbers, so E_ref is a deterministic function of r for a
seed, and its differences between two r are not drowned by draw-to-draw noise. K is
`EstimatorConfig.reference_draws`. The Monte-Carlo standard error of E_ref^2 is the draws'
sample standard deviation over sqrt(K); that of E_ref is it over 2 E_ref (delta method).

Under the deterministic "threshold" law every p is 0 or 1, every draw is the hard objective,
and E_ref = E_hard with standard error 0: it is computed once, not K times.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from diffsense.metrics._estimators import _clipped_logit  # the relaxed draw's clipping

# Folded into each variant's noise key to give the reference's uniforms their own stream.
_REFERENCE_STREAM = 0x13


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class ReferenceEvaluation:
    """E_ref at one r, with its Monte-Carlo standard error.

    Attributes:
        e2: [] E_ref^2, the mean of the draws' hard objective [m^2].
        e2_se: [] its standard error [m^2].
        e: [] E_ref [m].
        e_se: [] its standard error [m].
        draws: [K] the hard objective of each draw [m^2] (K = 1 for a deterministic law).
    """

    e2: Float[Array, ""]
    e2_se: Float[Array, ""]
    e: Float[Array, ""]
    e_se: Float[Array, ""]
    draws: Float[Array, " K"]


def is_deterministic(sensor: Any) -> bool:
    """True when every detection of `sensor` is a deterministic threshold (its hard p is 0/1):
    a radar or camera with the "threshold" law, or a suite of such. A custom sensor is assumed
    probabilistic (its reference is then drawn)."""
    members = getattr(sensor, "members", None)
    if members is not None:
        return all(is_deterministic(m) for m in members)
    detection = getattr(getattr(sensor, "config", None), "detection", None)
    return detection is not None and detection.law == "threshold"


def declares_random_law(sensor: Any) -> bool:
    """True when `sensor` declares a probabilistic detection law (a radar or camera whose
    `[detection] law` is not "threshold", or a suite with such a member). A custom sensor
    declares none: its hard detections are taken as its own."""
    members = getattr(sensor, "members", None)
    if members is not None:
        return any(declares_random_law(m) for m in members)
    detection = getattr(getattr(sensor, "config", None), "detection", None)
    return detection is not None and detection.law != "threshold"


def reference_uniforms(noise_key: Array, draw: Array, shape: tuple[int, ...], dtype) -> Float[Array, "N T V"]:
    """The uniforms in [0, 1) of reference draw `draw`, one [T, V] array per variant's key."""
    def one(key):
        stream = jax.random.fold_in(jax.random.fold_in(key, _REFERENCE_STREAM), draw)
        return jax.random.uniform(stream, shape, dtype=dtype)

    return jax.vmap(one)(noise_key)


def summarise(draws: Float[Array, " K"]) -> ReferenceEvaluation:
    """Mean and standard error of the draws' hard objective [m^2], and E_ref [m] with its own."""
    k = draws.shape[0]
    e2 = jnp.mean(draws)
    e2_se = jnp.std(draws, ddof=1) / jnp.sqrt(k) if k > 1 else jnp.zeros_like(e2)
    positive = e2 > 0
    e = jnp.where(positive, jnp.sqrt(jnp.where(positive, e2, 1.0)), 0.0)
    e_se = jnp.where(positive, e2_se / (2.0 * jnp.where(positive, e, 1.0)), 0.0)
    return ReferenceEvaluation(e2=e2, e2_se=e2_se, e=e, e_se=e_se, draws=draws)


def reference_draw_margins(objective: Any, r: Any, draws: int) -> Float[Array, "K N T V"]:
    """|logit p - logit u| of each of the first `draws` reference draws at r [logit units].

    How far each (draw, variant, frame, vehicle) detection is from flipping: the relaxed
    reference at temperature lambda differs from its hard draw by sigmoid(-margin / lambda), so the
    smallest margins say which draws carry the relaxed estimator's gap to E_ref. `objective` is a
    `diffsense.metrics.Objective`; r its parameters (a dict, or the value of a one-parameter problem).
    """
    p = objective._sensor_detections(objective.point(r), "hard").p_detect
    u = jax.vmap(lambda d: reference_uniforms(objective.data.noise_key, d, p.shape[1:], p.dtype))(jnp.arange(draws))
    return jnp.abs(_clipped_logit(p)[None] - _clipped_logit(u))
