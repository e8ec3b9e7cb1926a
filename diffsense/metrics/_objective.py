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

from diffsense.metrics._estimators import EstimatorConfig, mc_uniforms, relaxed_bernoulli
from diffsense.metrics._sharding import shard_leading_axis
from diffsense.scene import Scene
from diffsense.sensors._datatypes import Detections
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

    Build with `make_objective`. Exactly three programs are compiled, once per shape: the soft
    value-and-gradient, the hard evaluation (E and per-horizon RMSE together) and the detections.
    Every evaluation is memoised by (r, tau), so asking again for a point the solver has already
    visited (for a figure, a table) costs nothing.
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
        self._vg_jit = jax.jit(jax.value_and_grad(self.traced_e2))
        self._hard_jit = jax.jit(self._hard_eval)
        self._detections_jit = jax.jit(self._detections, static_argnums=3)
        self._soft_cache: dict[tuple[float, float], tuple[float, float]] = {}
        self._hard_cache: dict[float, tuple[float, np.ndarray, np.ndarray]] = {}
        self.counts = {"soft": 0, "hard": 0}

    # -- pure functions of (r, fixed data) ------------------------------------------------------
    def _predict_nI(self, data: ObjectiveData, inputs: PredictorInputs) -> Float[Array, "N I 25 2"]:
        return self._predict(data.model, inputs).reshape(data.gt_pred.shape)

    def _detect_all(self, r, tau, data: ObjectiveData, mode: Mode) -> Detections:
        # r and tau may come in at a wider float type than the data (a float64 outer solver
        # over a float32 objective): compute at the data's.
        r, tau = jnp.asarray(r).astype(self.dtype), jnp.asarray(tau).astype(self.dtype)
        return jax.vmap(lambda s, k: self._detect(s, r, tau, mode, k))(data.scenes, data.noise_key)

    def _soft_mean(self, r, tau, data: ObjectiveData, reduce: Callable[[Array], Array]) -> Array:
        """reduce(predictions [N, I, 25, 2]) with soft detections, averaged over the estimator's
        samples (one pass for mean-field)."""
        det = self._detect_all(r, tau, data, "soft")
        if self.estimator.kind != "mc":
            return reduce(self._predict_nI(data, _inputs(data.scenes, det, self.frames, self.fill)))

        # Rematerialised: reverse mode would otherwise keep every sample's CS-LSTM activations
        # (on the default problem K = 64 did not fit in 24 GB). Each sample's
        # forward pass is recomputed in the backward pass instead, so memory does not grow with K.
        @jax.checkpoint
        def one_sample(uniform):
            sample = relaxed_bernoulli(det.p_detect, uniform, self.estimator.relax_temperature)
            d = dataclasses.replace(det, p_detect=sample)
            return reduce(self._predict_nI(data, _inputs(data.scenes, d, self.frames, self.fill)))

        return jnp.mean(jax.lax.map(one_sample, jnp.swapaxes(data.mc_uniform, 0, 1)), axis=0)

    def traced_e2(self, r, tau, data: ObjectiveData | None = None):
        """Soft E^2(r, tau) [m^2] as a pure, traceable function (for jax transformations)."""
        data = self.data if data is None else data
        return self._soft_mean(r, tau, data, lambda pred: _mean_sq_error(pred, data.gt_pred, data.weight))

    def traced_sq_error(self, r, tau, data: ObjectiveData | None = None) -> Float[Array, "N 25"]:
        """The soft E^2 split by scene variant and horizon step, as a pure, traceable function.

        Element [n, h] is the squared distance [m^2] between the sensor-input and the
        ground-truth-input predictions of variant n at horizon step h (0.2 s ... 5 s), averaged
        over prediction instants (and over samples for the Monte-Carlo estimator). E^2 is its
        variant-weighted mean over n of the mean over h: `traced_e2` up to rounding, so
        d/dr of any weighting of it says which variants and steps drive dE^2/dr.
        """
        data = self.data if data is None else data

        def by_step(pred):
            return jnp.mean(jnp.sum((pred - data.gt_pred) ** 2, axis=-1), axis=1)  # [N, 25]

        return self._soft_mean(r, tau, data, by_step)

    def _hard_eval(self, r, data: ObjectiveData):
        """Hard E^2 and per-scenario RMSE against the true future ([S, 25], GT and sensor)."""
        det = self._detect_all(r, 1.0, data, "hard")
        pred = self._predict_nI(data, _inputs(data.scenes, det, self.frames, self.fill))
        onehot = jax.nn.one_hot(data.scenario, self.num_scenarios) * data.weight[:, None]
        count = jnp.maximum(jnp.sum(onehot, axis=0), 1.0)[:, None]  # a scenario may be absent

        def rmse(p):
            sq = jnp.mean(jnp.sum((p - data.true_fut) ** 2, axis=-1), axis=1)  # [N, 25]
            return jnp.sqrt(onehot.T @ sq / count)

        return _mean_sq_error(pred, data.gt_pred, data.weight), rmse(data.gt_pred), rmse(pred)

    def _detections(self, r, tau, data: ObjectiveData, mode: Mode) -> Detections:
        return self._detect_all(r, tau, data, mode)

    # -- the public, compiled and memoised face -------------------------------------------------
    def value_and_grad(self, r: float, tau: float = 1.0) -> tuple[float, float]:
        """Soft E^2 [m^2] and dE^2/dr at r, gate temperatures scaled by tau."""
        key = (float(r), float(tau))
        if key not in self._soft_cache:
            self.counts["soft"] += 1
            v, g = self._vg_jit(jnp.asarray(key[0], self.dtype), jnp.asarray(key[1], self.dtype), self.data)
            self._soft_cache[key] = (float(v), float(g))
        return self._soft_cache[key]

    def e2_soft(self, r: float, tau: float = 1.0) -> float:
        """Soft E^2 [m^2] at r (the estimator's value)."""
        return self.value_and_grad(r, tau)[0]

    def _hard(self, r: float) -> tuple[float, np.ndarray, np.ndarray]:
        key = float(r)
        if key not in self._hard_cache:
            self.counts["hard"] += 1
            e2, gt, sensor = self._hard_jit(jnp.asarray(key, self.dtype), self.data)
            self._hard_cache[key] = (float(e2), np.asarray(gt), np.asarray(sensor))
        return self._hard_cache[key]

    def e_hard(self, r: float) -> float:
        """E [m] with hard (0/1) detections: the reference quality of a parameter value."""
        return float(np.sqrt(max(self._hard(r)[0], 0.0)))

    def horizon_rmse(self, r: float) -> tuple[np.ndarray, np.ndarray]:
        """With hard detections at r: ([S, 25] RMSE of the ground-truth-input predictions against
        the true future, [S, 25] of the sensor-input ones) [m], per scenario."""
        _, gt, sensor = self._hard(r)
        return gt, sensor

    def detections(self, r: float, mode: Mode = "hard", tau: float = 1.0) -> Detections:
        """The sensor's detections of every variant at r."""
        return self._detections_jit(jnp.asarray(r, self.dtype), jnp.asarray(tau, self.dtype), self.data, mode)

    def forget(self) -> None:
        """Drop the memoised evaluations (the compiled programs stay): for timing a solve again."""
        self._soft_cache.clear()
        self._hard_cache.clear()

    def solver_fns(self, dtype=jnp.float64) -> tuple[Callable[[Array, Array], Array], Callable[[Array], float]]:
        """(e2_soft, e_hard) in the form `diffsense.solve.solve` takes.

        `e2_soft(r, tau)` is traceable and differentiable in r, but it calls this objective's
        compiled value-and-gradient program through a host callback instead of being traced
        again: a solver that compiles its own loop around it does not compile the CS-LSTM a
        second time. (Its tau-derivative is not provided.)
        """
        spec = jax.ShapeDtypeStruct((), dtype)

        def host_vg(r, tau):
            v, g = self.value_and_grad(float(r), float(tau))
            return np.asarray(v, dtype), np.asarray(g, dtype)

        def call(r, tau):
            return jax.pure_callback(host_vg, (spec, spec), r, tau)

        @jax.custom_jvp
        def e2_soft(r, tau):
            return call(r, tau)[0]

        @e2_soft.defjvp
        def _jvp(primals, tangents):
            v, g = call(*primals)
            return v, g * tangents[0]

        return e2_soft, lambda r: self.e_hard(float(r))

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
