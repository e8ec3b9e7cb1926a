"""What each drawn estimator samples: the detection draws the objective averages its soft value
over (relaxed-reference and straight-through: the reference's own draws, relaxed; mc: its own
uniforms), or None for the one-pass mean-field."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

import jax.numpy as jnp
from jaxtyping import Array

from diffsense.metrics._estimators import relaxed_bernoulli, relaxed_draw
from diffsense.metrics._reference import MC_STREAM, detection_events, is_deterministic
from diffsense.sensors import Suite


def estimator_samples(objective: Any, r: Mapping[str, Any], tau: Any) -> tuple[Array, Callable, Callable | None] | None:
    """The drawn estimators' samples of `objective` (a `diffsense.metrics.Objective`) at r (a
    dict): (what each relaxed sample is indexed by, sample -> relaxed Detections, draw -> hard
    Detections for straight-through, whose value is drawn on all K reference draws, or None);
    None for the one-pass mean-field."""
    kind, key = objective.estimator_kind, objective.data.noise_key
    if kind in ("relaxed-reference", "straight-through") and not is_deterministic(objective.sensor):
        # The reference's own events (exact occlusion geometry; a suite's members one by
        # one): under a probabilistic law p is already smooth in the sensor's parameters,
        # and only the draw needs relaxing, so the estimate tends to E_ref itself as the
        # temperature falls.
        events = detection_events(objective, r)
        temperature = objective.estimator.reference_temperature * jnp.asarray(tau, objective.dtype)
        relax = lambda k: events.combine([relaxed_draw(p, u, temperature)
                                          for p, u in zip(events.p_detect, events.uniforms(key, k))])
        hard = lambda k: events.combine([(u < p).astype(objective.dtype)
                                         for p, u in zip(events.p_detect, events.uniforms(key, k))])
        relaxed = min(objective.estimator.gradient_draws, objective.estimator.reference_draws)
        return jnp.arange(relaxed), relax, hard if kind == "straight-through" else None
    if kind != "mc":
        return None
    lam = objective.estimator.relax_temperature
    if isinstance(objective.sensor, Suite):
        # Each member drawn on its own, from its own uniforms, as E_ref draws them: a sample's
        # track is the fusion of the members that drew a detection.
        events = detection_events(objective, r, "soft", tau)
        relax = lambda k: events.combine([relaxed_draw(p, u, lam)
                                          for p, u in zip(events.p_detect, events.uniforms(key, k, MC_STREAM))])
        return jnp.arange(objective.estimator.samples), relax, None
    det = objective.detections(r, "soft", tau)
    relax = lambda u: dataclasses.replace(det, p_detect=relaxed_bernoulli(det.p_detect, u, lam))
    return jnp.swapaxes(objective.data.mc_uniform, 0, 1), relax, None
