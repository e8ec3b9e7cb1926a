"""The reference objective E_ref(r): the expectation of the hard objective over detection draws.

Where detection is a random event (a probabilistic `[detection] law`, `diffsense.sensors._laws`),
the sensor gives for every (frame, vehicle) the probability p of the physical detection event.
E_ref^2 is the mean over K draws of the hard objective (Eq. 12's E^2, or J of "tracked"), each
draw detecting (frame, vehicle) when u < p for a uniform u:

    E_ref(r)^2 = (1/K) sum_k E_hard^2(r; detections 1[u_k < p(r)])                       [m^2]

A suite's members detect independently (`diffsense.sensors.Suite`), so a draw decides each
member's detection with its own uniform and fuses the measurements of the members that drew
one (inverse-variance weighting): the track's position in a draw is that of the members that saw
the car, not the fused expectation over which members might have. The uniforms come from each
variant's measurement-noise key folded with a fixed stream number and the draw's index (and,
for a suite, the member's index): common random numbers, so E_ref is a deterministic function of r for a
seed, and its differences between two r are not drowned by draw-to-draw noise. K is
`EstimatorConfig.reference_draws`. The Monte-Carlo standard error of E_ref^2 is the draws'
sample standard deviation over sqrt(K); that of E_ref is it over 2 E_ref (delta method).

Under the deterministic "threshold" law every p is 0 or 1, every draw is the hard objective,
and E_ref = E_hard with standard error 0: it is computed once, not K times.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from diffsense import runtime
from diffsense.metrics._estimators import _clipped_logit  # the relaxed draw's clipping
from diffsense.sensors import Detections, Suite, fuse_members

# Folded into each variant's noise key to give the reference's uniforms their own stream, and
# the Monte-Carlo estimator's draws of a suite's members theirs (independent of the reference's).
_REFERENCE_STREAM = 0x13
MC_STREAM = 0x17


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class DrawnParts:
    """What the draws' hard evaluations are made of: the pieces E_ref's breakdown is read from
    (`diffsense.metrics.breakdown`), kept per draw where a part's membership changes with the
    draw (an instant's coverage class) and averaged over the draws where it does not.

    Attributes:
        sq_instant: [K, N, I] each draw's squared distance per instant, mean over horizon steps [m^2].
        coverage: [K, N, I, 3] each draw's coverage classes, 0/1 (`_coverage.py`).
        sq_error: [N, F] the draws' mean squared distance per variant and horizon step [m^2].
        sq_true_gt: [N, I, F] the ground-truth-input prediction's squared error against the
            true future [m^2] (the same in every draw).
        sq_true_sensor: [N, I, F] the sensor-input prediction's, mean over the draws [m^2].
    """

    sq_instant: Float[Array, "K N I"]
    coverage: Float[Array, "K N I 3"]
    sq_error: Float[Array, "N F"]
    sq_true_gt: Float[Array, "N I F"]
    sq_true_sensor: Float[Array, "N I F"]


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
        parts: the draws' pieces its breakdown is read from (None where only the value was kept).
    """

    e2: Float[Array, ""]
    e2_se: Float[Array, ""]
    e: Float[Array, ""]
    e_se: Float[Array, ""]
    draws: Float[Array, " K"]
    parts: DrawnParts | None = None


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


def reference_uniforms(noise_key: Array, draw: Array, shape: tuple[int, ...], dtype,
                       member: int | None = None, stream_id: int = _REFERENCE_STREAM) -> Float[Array, "N T V"]:
    """The uniforms in [0, 1) of reference draw `draw`, one [T, V] array per variant's key
    (suite member `member`'s own stream when given; `stream_id` MC_STREAM for the Monte-Carlo
    estimator's draws)."""
    def one(key):
        stream = jax.random.fold_in(jax.random.fold_in(key, stream_id), draw)
        if member is not None:
            stream = jax.random.fold_in(stream, member)
        return runtime.uniform(stream, shape, dtype)

    return jax.vmap(one)(noise_key)


@dataclasses.dataclass(frozen=True)
class DetectionEvents:
    """The independent detection events of every variant at one r, and what a draw of them gives.

    Attributes:
        p_detect: one [N, T, V] probability per event: the sensor's own, or each suite member's.
        members: the events' uniform streams: (None,) for one sensor, (0, ..., M-1) for a suite.
        combine: drawn outcomes (one [N, T, V] array per event: 0/1, or relaxed draws) -> the
            Detections the tracks are built from (a suite's fused).
    """

    p_detect: list[Float[Array, "N T V"]]
    members: tuple[int | None, ...]
    combine: Callable[[Sequence[Array]], Detections]

    def uniforms(self, noise_key: Array, draw: Array, stream_id: int = _REFERENCE_STREAM) -> list[Float[Array, "N T V"]]:
        """Each event's uniforms of reference draw `draw` (common random numbers), or of the
        Monte-Carlo estimator's with `stream_id` MC_STREAM."""
        p = self.p_detect[0]
        return [reference_uniforms(noise_key, draw, p.shape[1:], p.dtype, m, stream_id) for m in self.members]


def detection_events(objective: Any, r: Any, mode: str = "hard", tau: Any = 1.0) -> DetectionEvents:
    """The detection events of `objective` (a `diffsense.metrics.Objective`) at r (a dict): the
    sensor's unrelaxed probabilities ("hard", the reference's), or its relaxed gates' at the
    temperature multiplier `tau` ("soft", the Monte-Carlo estimator's)."""
    sensor = objective.sensor
    if not isinstance(sensor, Suite):
        det = objective._sensor_detections(r, mode, tau)
        return DetectionEvents([det.p_detect], (None,), lambda drawn: dataclasses.replace(det, p_detect=drawn[0]))
    tau = jnp.asarray(tau).astype(objective.dtype)
    views = objective._per_variant(
        r, lambda s, p, k, w: sensor.member_views(s, p, k, mode=mode, temperature=tau, weather=w))
    scenes = objective.data.scenes
    return DetectionEvents([d.p_detect for d, _ in views], tuple(range(len(views))),
                           lambda drawn: fuse_members(scenes, views, drawn)[0])


def safe_sqrt(x: Array) -> Array:
    """sqrt(x) for x >= 0 with a finite gradient at 0 (where sqrt's is infinite); NaN stays NaN
    (an E^2 that could not be computed is never reported as the best value, 0)."""
    positive = x > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, x, 1.0)), jnp.where(jnp.isnan(x), x, 0.0))


def summarise(draws: Float[Array, " K"], parts: DrawnParts | None = None) -> ReferenceEvaluation:
    """Mean and standard error of the draws' hard objective [m^2], and E_ref [m] with its own."""
    k = draws.shape[0]
    e2 = jnp.mean(draws)
    # The variance under a safe sqrt: jnp.std's gradient is NaN when every draw is equal.
    var_of_mean = jnp.sum((draws - e2) ** 2) / ((k - 1) * k) if k > 1 else jnp.zeros_like(e2)
    e2_se = safe_sqrt(var_of_mean)
    positive = e2 > 0
    e = safe_sqrt(e2)
    e_se = jnp.where(positive, e2_se / (2.0 * jnp.where(positive, e, 1.0)), 0.0)
    return ReferenceEvaluation(e2=e2, e2_se=e2_se, e=e, e_se=e_se, draws=draws, parts=parts)


def reference_draw_margins(objective: Any, r: Any, draws: int) -> Float[Array, "K N T V"]:
    """|logit p - logit u| of each of the first `draws` reference draws at r [logit units].

    How far each (draw, variant, frame, vehicle) detection is from flipping: the relaxed
    reference at temperature lambda differs from its hard draw by sigmoid(-margin / lambda), so the
    smallest margins say which draws carry the relaxed estimator's gap to E_ref. For a suite it is
    the smallest over the members (the member nearest to flipping). `objective` is a
    `diffsense.metrics.Objective`; r its parameters (a dict, or the value of a one-parameter problem).
    """
    events = detection_events(objective, objective.point(r))

    def one(draw):
        us = events.uniforms(objective.data.noise_key, draw)
        margins = [jnp.abs(_clipped_logit(p) - _clipped_logit(u)) for p, u in zip(events.p_detect, us)]
        return jnp.min(jnp.stack(margins), axis=0)

    return jax.vmap(one)(jnp.arange(draws))
