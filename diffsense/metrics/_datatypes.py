"""The fixed data of E(r) and the hard evaluation's record: small frozen pytrees, shapes in their
docstrings (N scene variants, I prediction instants, F horizon steps, S scenarios, K draws)."""

from __future__ import annotations

import dataclasses

import jax
from jaxtyping import Array, Float, Int

from diffsense.scene import Scene


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class ObjectiveData:
    """Everything E(r) needs that does not depend on r; N scene variants, I instants, F steps.

    Attributes:
        scenes: [N, T, V] ground truth (padded variants repeat a real one).
        scenario: [N] index of the scenario each variant belongs to.
        weight: [N] 1 for real variants, 0 for padding added to shard evenly over devices.
        gt_pred: [N, I, F, 2] predictions from ground-truth histories [m].
        true_fut: [N, I, F, 2] the target's true future [m].
        noise_key: [N, ...] the PRNG key of each variant's measurement noise.
        mc_uniform: [N, K, T, V] fixed uniform draws of the Monte-Carlo estimator (K = 0 if unused).
    """

    scenes: Scene
    scenario: Int[Array, " N"]
    weight: Float[Array, " N"]
    gt_pred: Float[Array, "N I F 2"]
    true_fut: Float[Array, "N I F 2"]
    noise_key: Array
    mc_uniform: Float[Array, "N K T V"]


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class HardEvaluation:
    """E with hard (0/1) detections, and both predictions against the true future.

    Attributes:
        e2: [] E^2 [m^2] (Eq. 12, pooled).
        sq_error: [N, F] the sensor-input against the ground-truth-input prediction, squared
            distance per variant and horizon step, mean over instants [m^2].
        rmse_gt: [S, F] RMSE of the ground-truth-input prediction against the true future, per
            scenario and horizon step [m].
        rmse_sensor: [S, F] the same for the sensor-input prediction [m].
        sq_instant: [N, I] the squared distance per instant, mean over horizon steps [m^2].
        coverage: [N, I, 3] 0/1: target detected at the instant, at least once in the history
            window, throughout it (see `_coverage.py`).
        sq_true_gt: [N, I, F] squared error of the ground-truth-input prediction against the
            true future [m^2]; sq_true_sensor the same for the sensor-input prediction.
        objective: [] the question's value (`e2` for "eq12"; J for "tracked") [m^2].
        p_detect: [N, T, V] the 0/1 detections themselves (a suite's fused ones), so a record
            of what the sensor saw needs no second program.
    """

    e2: Float[Array, ""]
    sq_error: Float[Array, "N F"]
    rmse_gt: Float[Array, "S F"]
    rmse_sensor: Float[Array, "S F"]
    sq_instant: Float[Array, "N I"]
    coverage: Float[Array, "N I 3"]
    sq_true_gt: Float[Array, "N I F"]
    sq_true_sensor: Float[Array, "N I F"]
    objective: Float[Array, ""]
    p_detect: Float[Array, "N T V"]
