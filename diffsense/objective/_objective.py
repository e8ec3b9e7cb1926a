"""E_RMSE(r): the paper's Eq. 12 between predictions from ground-truth and from sensor histories.

    E(r)^2 = mean over prediction instants i of all scene variants and horizon steps h of
             || y_GT[i, h] - y_r[i, h] ||^2                                    [m^2]

The ground-truth predictions y_GT do not depend on r and are computed once. No instant is ever
dropped: a missed target enters through the fill policy, so a blind sensor is penalised.
The optimiser works on E^2 (the gradient of sqrt is NaN at 0); E is reported.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, Literal

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from diffsense.objective._estimators import EstimatorConfig, mc_uniforms, relaxed_bernoulli
from diffsense.objective._sharding import shard_leading_axis
from diffsense.scene import Scene
from diffsense.sensor._datatypes import Detections
from diffsense.tracks import (
    FillPolicy,
    PredictorInputs,
    build_inputs,
    flatten_instants,
    ground_truth_detections,
    true_future,
)

Mode = Literal["soft", "hard"]
# detect(scene [T, V], r, tau_scale, mode, key) -> Detections [T, V]; the key fixes the
# measurement-noise draws of that scene variant (common random numbers across r).
DetectFn = Callable[[Scene, Array, Array, Mode, Array], Detections]
# predict(model, inputs with batch B) -> future means [B, 25, 2] in the same SI frame; `model`
# is a pytree (the predictor's weights) passed as data so that jit does not bake it in.
PredictFn = Callable[[Any, PredictorInputs], Float[Array, "B 25 2"]]


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class ObjectiveData:
    """Everything E(r) needs that does not depend on r; N scene variants, I instants each.

    Attributes:
        scenes: [N, T, V] ground truth (padded variants repeat a real one).
        scenario: [N] index of the scenario each variant belongs to.
        weight: [N] 1 for real variants, 0 for padding added to shard evenly over devices.
        gt_pred: [N, I, 25, 2] predictions from ground-truth histories [m].
        true_fut: [N, I, 25, 2] the target's true future [m].
        noise_key: [N, ...] the PRNG key of each variant's measurement noise.
        mc_uniform: [N, K, T, V] fixed uniform draws of the Monte-Carlo estimator (K = 0 if unused).
        model: the predictor's weights (any pytree the predict function takes).
    """

    scenes: Scene
    scenario: Int[Array, " N"]
    weight: Float[Array, " N"]
    gt_pred: Float[Array, "N I 25 2"]
    true_fut: Float[Array, "N I 25 2"]
    noise_key: Array
    mc_uniform: Float[Array, "N K T V"]
    model: Any


def _inputs(scenes: Scene, det: Detections, frames: np.ndarray, fill: FillPolicy) -> PredictorInputs:
    """Predictor inputs for every variant and instant, flattened to [N * I, ...]."""
    per_scene = jax.vmap(lambda s, d: build_inputs(s, d, frames, fill))(scenes, det)
    return flatten_instants(per_scene)


def _mean_sq_error(pred: Float[Array, "N I 25 2"], ref: Float[Array, "N I 25 2"], weight: Float[Array, " N"]):
    sq = jnp.sum((pred - ref) ** 2, axis=-1)  # [N, I, 25]
    per_variant = jnp.mean(sq, axis=(1, 2))
    return jnp.sum(weight * per_variant) / jnp.sum(weight)


class Objective:
    """E(r) for one sensor parameter over a batch of scene variants.

    Build with `make_objective`. Methods are jitted once per shape; r and tau are scalars.
    """

    def __init__(self, data: ObjectiveData, frames: np.ndarray, detect: DetectFn, predict: PredictFn,
                 fill: FillPolicy, estimator: EstimatorConfig, num_scenarios: int):
        self.data = data
        self.frames = frames
        self.fill = fill
        self.estimator = estimator
        self.num_scenarios = num_scenarios
        self._detect = detect
        self._predict = predict
        # The fixed data is an argument, not a closure: XLA must not fold it in as a constant.
        self._e2_and_grad = jax.jit(jax.value_and_grad(self._e2_soft))
        self._e2_soft_jit = jax.jit(self._e2_soft)
        self._e2_hard_jit = jax.jit(self._e2_hard)
        self._horizon_jit = jax.jit(self._horizon_rmse, static_argnums=3)
        self._detections_jit = jax.jit(self._detections, static_argnums=3)

    # -- pure functions of (r, fixed data) ------------------------------------------------------
    def _predict_nI(self, data: ObjectiveData, inputs: PredictorInputs) -> Float[Array, "N I 25 2"]:
        return self._predict(data.model, inputs).reshape(data.gt_pred.shape)

    def _detect_all(self, r, tau, data: ObjectiveData, mode: Mode) -> Detections:
        return jax.vmap(lambda s, k: self._detect(s, r, tau, mode, k))(data.scenes, data.noise_key)

    def _e2_soft(self, r, tau, data: ObjectiveData):
        det = self._detect_all(r, tau, data, "soft")
        if self.estimator.kind != "mc":
            pred = self._predict_nI(data, _inputs(data.scenes, det, self.frames, self.fill))
            return _mean_sq_error(pred, data.gt_pred, data.weight)

        def one_sample(uniform):
            sample = relaxed_bernoulli(det.p_detect, uniform, self.estimator.relax_temperature)
            d = dataclasses.replace(det, p_detect=sample)
            pred = self._predict_nI(data, _inputs(data.scenes, d, self.frames, self.fill))
            return _mean_sq_error(pred, data.gt_pred, data.weight)

        return jnp.mean(jax.lax.map(one_sample, jnp.swapaxes(data.mc_uniform, 0, 1)))

    def _e2_hard(self, r, data: ObjectiveData):
        det = self._detect_all(r, jnp.ones_like(r), data, "hard")
        pred = self._predict_nI(data, _inputs(data.scenes, det, self.frames, self.fill))
        return _mean_sq_error(pred, data.gt_pred, data.weight)

    def _detections(self, r, tau, data: ObjectiveData, mode: Mode) -> Detections:
        return self._detect_all(r, tau, data, mode)

    def _horizon_rmse(self, r, tau, data: ObjectiveData, mode: Mode):
        """Per-scenario RMSE against the true future at each horizon step, [S, 25] twice."""
        det = self._detect_all(r, tau, data, mode)
        pred = self._predict_nI(data, _inputs(data.scenes, det, self.frames, self.fill))
        onehot = jax.nn.one_hot(data.scenario, self.num_scenarios) * data.weight[:, None]
        count = jnp.maximum(jnp.sum(onehot, axis=0), 1.0)[:, None]  # a scenario may be absent

        def rmse(p):
            sq = jnp.mean(jnp.sum((p - data.true_fut) ** 2, axis=-1), axis=1)  # [N, 25]
            return jnp.sqrt(onehot.T @ sq / count)

        return rmse(data.gt_pred), rmse(pred)

    # -- the public, jitted face ---------------------------------------------------------------
    def e2_and_grad(self, r: float, tau: float = 1.0) -> tuple[Array, Array]:
        """Soft E^2 [m^2] and dE^2/dr at r, temperatures scaled by tau."""
        return self._e2_and_grad(jnp.asarray(r, self.dtype), jnp.asarray(tau, self.dtype), self.data)

    def e2_soft(self, r: float, tau: float = 1.0) -> Array:
        """Soft E^2 [m^2] at r (the estimator's value, no gradient computed)."""
        return self._e2_soft_jit(jnp.asarray(r, self.dtype), jnp.asarray(tau, self.dtype), self.data)

    def e_hard(self, r: float) -> float:
        """E [m] with hard (0/1) detections: the reference quality of a parameter value."""
        return float(jnp.sqrt(self._e2_hard_jit(jnp.asarray(r, self.dtype), self.data)))

    def horizon_rmse(self, r: float, mode: Mode = "hard", tau: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """([S, 25] RMSE of ground-truth-input predictions, [S, 25] of sensor-input ones) [m]."""
        gt, sensor = self._horizon_jit(jnp.asarray(r, self.dtype), jnp.asarray(tau, self.dtype), self.data, mode)
        return np.asarray(gt), np.asarray(sensor)

    def detections(self, r: float, mode: Mode = "hard", tau: float = 1.0) -> Detections:
        """The sensor's detections of every variant at r."""
        return self._detections_jit(jnp.asarray(r, self.dtype), jnp.asarray(tau, self.dtype), self.data, mode)

    @property
    def dtype(self):
        return self.data.gt_pred.dtype


def make_objective(
    scenes: Scene,
    scenario: Int[Array, " N"],
    frames: np.ndarray,
    detect: DetectFn,
    predict: PredictFn,
    model: Any = None,
    fill: FillPolicy = "hold",
    estimator: EstimatorConfig = EstimatorConfig(),
    key: Array | None = None,
    num_scenarios: int | None = None,
    shard: bool = True,
) -> Objective:
    """Build E(r) over the scene variants `scenes` [N, T, V].

    `key` fixes every random draw (measurement noise, Monte-Carlo uniforms): same key, same E(r).
    Ground-truth predictions are computed here, once. With several local JAX devices the
    variants are sharded over them (padding with zero-weight copies to a multiple of the
    device count); with one device nothing changes.
    """
    frames = np.asarray(frames, dtype=np.int32)
    scenario = jnp.asarray(scenario, jnp.int32)
    n = scenario.shape[0]
    dtype = scenes.x_m.dtype
    weight = jnp.ones((n,), dtype)
    key = jax.random.PRNGKey(0) if key is None else key
    noise_key, mc_key = jax.random.split(key)
    # Random draws are made per real variant before any padding, so sharding never changes them.
    noise_keys = jax.random.split(noise_key, n)
    k = estimator.samples if estimator.kind == "mc" else 0
    uniform = jax.vmap(lambda kk: mc_uniforms(kk, k, scenes.x_m.shape[1:], dtype))(jax.random.split(mc_key, n))
    fut = jax.vmap(lambda s: true_future(s, frames))(scenes)
    fixed = (scenes, scenario, weight, noise_keys, uniform, fut)
    if shard:
        fixed = shard_leading_axis(fixed, pad_weight_index=2)
    scenes, scenario, weight, noise_keys, uniform, fut = fixed
    gt_inputs = _inputs(scenes, jax.vmap(ground_truth_detections)(scenes), frames, fill)
    gt_pred = jax.jit(predict)(model, gt_inputs).reshape(scenario.shape[0], len(frames), -1, 2)
    data = ObjectiveData(scenes=scenes, scenario=scenario, weight=weight, gt_pred=gt_pred,
                         true_fut=fut.astype(gt_pred.dtype), noise_key=noise_keys, mc_uniform=uniform,
                         model=model)
    s = int(num_scenarios if num_scenarios is not None else int(jnp.max(scenario)) + 1)
    return Objective(data, frames, detect, predict, fill, estimator, s)
