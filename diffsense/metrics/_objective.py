"""E_RMSE(r): the paper's Eq. 12 between predictions from ground-truth and from sensor histories.

    E(r)^2 = mean over prediction instants i of all scene variants and horizon steps h of
             || y_GT[i, h] - y_r[i, h] ||^2                                    [m^2]

`Objective` is an equinox Module: a pure function of r (a dict of named sensor parameters) and
fixed data (scenes, ground-truth predictions, noise keys) held as pytree leaves, so `jax.jit`,
`jax.grad` and `jax.vmap` apply to it directly and nothing crosses to the host. The
ground-truth predictions y_GT do not depend on r and are computed once, when it is built. No
instant is ever dropped: a missed target enters through the fill policy, so a blind sensor is
penalised. Solvers work on E^2 (`e2`); `E(r)` is its square root with a gradient that stays
finite at E = 0.

Two questions can be asked (`question`):
- "eq12" (the default, the paper's): E over every instant. An instant whose target the sensor
  never saw in the history window predicts from a fill (a parked car under `zero`), so E also
  measures coverage.
- "tracked": the prediction error over the instants whose target has a track, each instant
  weighted by the probability q that the target was detected at least once in its history
  window, plus a price for the instants without one:
      J = sum_i q_i e_i^2 / (1 + sum_i q_i)  +  miss_penalty_m2 * (1 - mean_i q_i)      [m^2]
  The first term alone would let a blind sensor "win" (no tracked instant, no error); the
  penalty says what a missed track costs, in the units of a squared prediction error (the
  default 100 m^2: as bad as a 10 m RMS error). The 1 in the denominator is one pseudo-instant
  of zero error: without it, instants tracked with a tiny probability (a nearly blind soft
  sensor) would stand for all of them, and J would not tend to the hard J (the price alone)
  as the sensor goes blind; with hundreds of tracked instants it moves J by well under 1 %.
  Both terms are smooth in r and finite when no instant is tracked.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from diffsense.metrics._coverage import coverage_classes, p_tracked, target_window
from diffsense.metrics._datatypes import HardEvaluation, ObjectiveData
from diffsense.metrics._estimators import EstimatorConfig, straight_through
from diffsense.metrics._reference import (
    DrawnParts,
    ReferenceEvaluation,
    declares_random_law,
    detection_events,
    is_deterministic,
    safe_sqrt,
    summarise,
)
from diffsense.metrics._sampling import estimator_samples
from diffsense.predictors import InputSpec
from diffsense.runtime import InputError
from diffsense.sensors import Detections, Sensor, Weather
from diffsense.tracks import FillPolicy, build_inputs, flatten_instants

Mode = Literal["soft", "hard", "reference"]
Question = Literal["eq12", "tracked"]
QUESTIONS: tuple[str, ...] = ("eq12", "tracked")
Params = Mapping[str, Any]


def weighted_mean(per_variant: Float[Array, " N"], weight: Float[Array, " N"]) -> Float[Array, ""]:
    """Mean over real variants (padding has weight 0)."""
    return jnp.sum(weight * per_variant) / jnp.sum(weight)


class Objective(eqx.Module):
    """E(r) [m] of one sensor and one predictor over a batch of scene variants.

    Call it: `E(r)` (soft, the estimator's value at temperature multiplier `tau`),
    `E(r, mode="hard")` (0/1 detections, each probability's median) or
    `E(r, mode="reference")` (E_ref: the hard objective's expectation over detection draws,
    which the soft objective estimates; `reference` gives its standard error). r is a dict of named
    parameters of the sensor (`{"hfov_deg": 45.0}`); parameters it leaves out keep the
    sensor's defaults. `names` are the problem's free parameters (what a solver varies).
    `weather` (leaves [N], one per variant, like the data) is the scenes' ODD: E is
    differentiable in it.
    Build it with `diffsense.objective(problem)` or `make_objective`.
    """

    data: ObjectiveData
    sensor: Sensor
    predictor: Any
    weather: Weather
    names: tuple[str, ...] = eqx.field(static=True)
    frames: tuple[int, ...] = eqx.field(static=True)
    fill: FillPolicy = eqx.field(static=True)
    estimator: EstimatorConfig = eqx.field(static=True)
    scenario_names: tuple[str, ...] = eqx.field(static=True)
    question: Question = eqx.field(static=True, default="eq12")
    miss_penalty_m2: float = eqx.field(static=True, default=100.0)

    # Identity hashing lets `jax.jit(E)` take the module as the function to compile (a Module
    # hashes its fields by default, and arrays are not hashable). `jax.jit(E)` embeds E's data
    # in the program; `eqx.filter_jit` or passing E as an argument keeps it an input.
    def __hash__(self) -> int:
        return id(self)

    def __eq__(self, other) -> bool:
        return self is other

    def __call__(self, r: Params, mode: Mode = "soft", tau: float | Array = 1.0) -> Float[Array, ""]:
        """E [m] at r: soft (the estimator at temperature multiplier `tau`), hard, or the
        reference (the expectation of the hard objective over detection draws, `reference`)."""
        if mode == "hard":
            return safe_sqrt(self.hard(r).objective)
        if mode == "reference":
            return self.reference(r).e
        if mode != "soft":
            raise ValueError(f"mode must be 'soft', 'hard' or 'reference', got {mode!r}")
        return safe_sqrt(self.e2(r, tau))

    # -- the pieces ---------------------------------------------------------------------------
    @property
    def spec(self) -> InputSpec:
        """The predictor's input spec."""
        return self.predictor.spec

    @property
    def dtype(self):
        return self.data.gt_pred.dtype

    @property
    def estimator_kind(self) -> str:
        """The estimator E's soft value is: `estimator.kind`, with "auto" resolved. Under a
        probabilistic detection law "auto" is straight-through (E_ref's value, relaxed-reference's
        gradient) for one free parameter, whose solve judges on E_ref and roots the gradient, and
        relaxed-reference for several, whose BFGS line search compares values that must move
        with the gradient; under the threshold law and for a custom sensor it is mean-field."""
        kind = self.estimator.kind
        if kind != "auto":
            return kind
        if not declares_random_law(self.sensor):
            return "mean-field"
        return "straight-through" if len(self.names) == 1 else "relaxed-reference"

    def _params(self, r: Params) -> dict[str, Array]:
        # r may come at a wider float type than the data (a float64 solver over float32 data):
        # compute at the data's.
        if not isinstance(r, Mapping):
            raise InputError(f"r must be a dict of named parameters (e.g. {{{self.names[0]!r}: ...}}), "
                             f"got {type(r).__name__}" if self.names else "r must be a dict of named parameters")
        for name, value in r.items():
            self.sensor.spec(name).check(value)
        return {k: jnp.asarray(v).astype(self.dtype) for k, v in r.items()}

    def detections(self, r: Params, mode: Mode = "hard", tau: float | Array = 1.0) -> Detections:
        """The sensor's detections of every variant at r: [N, T, V].

        "hard" decides each detection by its probability's median (p >= 1/2): a probabilistic
        detection law's p is that of a random event (`reference` draws it); the threshold law's
        0/1 are their own median.
        """
        det = self._sensor_detections(r, mode, tau)
        if mode == "hard":
            det = dataclasses.replace(det, p_detect=(det.p_detect >= 0.5).astype(det.p_detect.dtype))
        return det

    def _per_variant(self, r: Params, look: Callable[[Any, dict[str, Array], Array, Weather], Any]) -> Any:
        """look(scene, params, noise key, weather) of every variant at r (vmapped over variants)."""
        params = self._params(r)
        weather = jax.tree.map(lambda v: jnp.asarray(v).astype(self.dtype), self.weather)
        return jax.vmap(lambda s, k, w: look(s, params, k, w))(self.data.scenes, self.data.noise_key, weather)

    def _sensor_detections(self, r: Params, mode: Mode, tau: float | Array = 1.0) -> Detections:
        tau = jnp.asarray(tau).astype(self.dtype)
        return self._per_variant(r, lambda s, p, k, w: self.sensor.detect(s, p, k, mode=mode, temperature=tau, weather=w))

    def _predict(self, det: Detections) -> Float[Array, "N I F 2"]:
        frames = jnp.asarray(self.frames)
        per_scene = jax.vmap(lambda s, d: build_inputs(s, d, frames, self.fill, self.spec))(self.data.scenes, det)
        return self.predictor(flatten_instants(per_scene)).reshape(self.data.gt_pred.shape)

    def _sq_error(self, pred: Float[Array, "N I F 2"]) -> Float[Array, "N F"]:
        return jnp.mean(jnp.sum((pred - self.data.gt_pred) ** 2, axis=-1), axis=1)

    def _target_window(self, det: Detections) -> Float[Array, "N I W"]:
        history = (self.spec.history_points - 1) * self.spec.frames_per_point(self.data.scenes.dt_s)
        frames = jnp.asarray(self.frames)
        return jax.vmap(lambda p: target_window(p, frames, history))(det.p_detect)

    def _question(self, pred: Float[Array, "N I F 2"], tracked: Float[Array, "N I"]) -> Float[Array, ""]:
        """The question's value [m^2] from predictions and the probability each instant is tracked."""
        sq = jnp.mean(jnp.sum((pred - self.data.gt_pred) ** 2, axis=-1), axis=-1)  # [N, I]
        w = self.data.weight
        if self.question == "eq12":
            return weighted_mean(jnp.mean(sq, axis=1), w)
        seen = jnp.sum(w[:, None] * tracked)
        error = jnp.sum(w[:, None] * tracked * sq) / (1.0 + seen)
        missed = 1.0 - seen / (jnp.sum(w) * tracked.shape[1])
        return error + self.miss_penalty_m2 * missed

    def _soft_mean(self, r: Params, tau, reduce: Callable[[Array, Detections], Array]) -> Array:
        """reduce(predictions [N, I, F, 2], detections) with soft detections, averaged over the
        estimator's samples (one pass for mean-field)."""
        sampled = estimator_samples(self, r, tau)
        if sampled is None:  # mean-field (and the drawn estimators under a deterministic law)
            det = self.detections(r, "soft", tau)
            return reduce(self._predict(det), det)
        draws, relax, hard = sampled

        # Rematerialised: reverse mode would otherwise keep every sample's predictor activations
        # (on the default problem K = 64 asked for 35 GB); each sample's forward pass is
        # recomputed in the backward pass instead, so memory does not grow with K.
        @jax.checkpoint
        def one_sample(draw):
            d = relax(draw)
            return reduce(self._predict(d), d)

        relaxed = jnp.mean(jax.lax.map(one_sample, draws), axis=0)
        if hard is None:
            return relaxed

        def one_hard(draw):
            d = hard(draw)
            return reduce(self._predict(d), d)

        # E_ref's value (all K hard draws), the relaxed draws' gradient
        value = jnp.mean(jax.lax.map(one_hard, jnp.arange(self.estimator.reference_draws)), axis=0)
        return straight_through(value, relaxed)

    def sq_error(self, r: Params, tau: float | Array = 1.0) -> Float[Array, "N F"]:
        """The soft E^2 split by scene variant and horizon step [m^2].

        Element [n, h] is the squared distance between the sensor-input and the
        ground-truth-input predictions of variant n at horizon step h, averaged over prediction
        instants (and over samples for the Monte-Carlo estimator). E^2 is its variant-weighted
        mean over n of the mean over h, so d/dr of any weighting of it says which variants and
        steps drive dE^2/dr.
        """
        return self._soft_mean(r, tau, lambda pred, det: self._sq_error(pred))

    def e2(self, r: Params, tau: float | Array = 1.0) -> Float[Array, ""]:
        """The soft value [m^2] solvers minimise (its gradient is finite everywhere): E^2 of
        Eq. 12, or J of the "tracked" question (module docstring)."""
        return self._soft_mean(r, tau, lambda pred, det: self._question(pred, p_tracked(self._target_window(det))))

    def hard(self, r: Params) -> HardEvaluation:
        """Hard E^2, its splits (variant and step, instant, coverage) and per-scenario RMSE
        against the true future."""
        det = self.detections(r, "hard")
        pred = self._predict(det)
        sq = self._sq_error(pred)
        e2 = weighted_mean(jnp.mean(sq, axis=1), self.data.weight)
        coverage = jax.vmap(coverage_classes)(self._target_window(det))
        onehot = jax.nn.one_hot(self.data.scenario, len(self.scenario_names)) * self.data.weight[:, None]
        count = jnp.maximum(jnp.sum(onehot, axis=0), 1.0)[:, None]  # a scenario may be absent

        def rmse(p):
            per_variant = jnp.mean(jnp.sum((p - self.data.true_fut) ** 2, axis=-1), axis=1)  # [N, F]
            return safe_sqrt(onehot.T @ per_variant / count)

        def sq_true(p):
            return jnp.sum((p - self.data.true_fut) ** 2, axis=-1)  # [N, I, F]

        return HardEvaluation(e2=e2, sq_error=sq, rmse_gt=rmse(self.data.gt_pred), rmse_sensor=rmse(pred),
                              sq_instant=jnp.mean(jnp.sum((pred - self.data.gt_pred) ** 2, axis=-1), axis=-1),
                              coverage=coverage, sq_true_gt=sq_true(self.data.gt_pred), sq_true_sensor=sq_true(pred),
                              objective=self._question(pred, coverage[..., 1]), p_detect=det.p_detect)

    def reference(self, r: Params, draws: Int[Array, " K"] | None = None) -> ReferenceEvaluation:
        """E_ref at r with its Monte-Carlo standard error: the mean of the hard objective over
        `estimator.reference_draws` detection draws with common random numbers (`_reference.py`).

        `draws`, the draws' indices, defaults to 0 ... K-1. Indices from K on are draws independent
        of E_ref's own: they judge a point chosen on E_ref (a solve's answer, a grid's best)
        without the noise it was chosen on."""
        sq_true_gt = jnp.sum((self.data.gt_pred - self.data.true_fut) ** 2, axis=-1)
        if is_deterministic(self.sensor):
            h = self.hard(r)
            return summarise(h.objective[None], DrawnParts(h.sq_instant[None], h.coverage[None], h.sq_error,
                                                           sq_true_gt, h.sq_true_sensor))
        events = detection_events(self, r)

        @jax.checkpoint
        def one_draw(draw):
            us = events.uniforms(self.data.noise_key, draw)
            d = events.combine([(u < p).astype(self.dtype) for p, u in zip(events.p_detect, us)])
            coverage = jax.vmap(coverage_classes)(self._target_window(d))
            pred = self._predict(d)
            sq = jnp.sum((pred - self.data.gt_pred) ** 2, axis=-1)  # [N, I, F]
            sq_true = jnp.sum((pred - self.data.true_fut) ** 2, axis=-1)
            return self._question(pred, coverage[..., 1]), (jnp.mean(sq, axis=-1), coverage, jnp.mean(sq, axis=1), sq_true)

        ids = jnp.arange(self.estimator.reference_draws) if draws is None else jnp.asarray(draws)
        values, (sq_instant, coverage, sq_error, sq_true) = jax.lax.map(one_draw, ids)
        return summarise(values, DrawnParts(sq_instant, coverage, jnp.mean(sq_error, axis=0), sq_true_gt,
                                            jnp.mean(sq_true, axis=0)))

    def point(self, values) -> dict[str, Array]:
        """r as a dict from values in the order of `names` (a scalar for one parameter)."""
        values = jnp.atleast_1d(jnp.asarray(values))
        return {name: values[i] for i, name in enumerate(self.names)}
