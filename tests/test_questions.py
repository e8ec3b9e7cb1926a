"""The objective's two questions and its hard evaluation, pinned to values worked by hand.

Eq. 12: E^2 is the variant-weighted mean over instants and horizon steps of the squared distance
between the sensor-input and the ground-truth-input prediction. "tracked":
J = sum_i q_i e_i^2 / (1 + sum_i q_i) + miss_penalty_m2 (1 - mean_i q_i), q_i the probability that
instant i's target was detected at least once in its 31-frame history window (0/1 when hard).

Three toy variants (scenarios 0, 1, 0) of four instants. For the hand-made errors the predictor
replays fixed predictions and the ground-truth-input ones are moved by a chosen distance on the
first five of the 25 horizon steps (x for variants 0 and 2, y for variant 1, so a mix-up of the
coordinate axis shows): each instant's squared error is that distance squared over 5.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.metrics import tracked_summary
from diffsense.predictors import CSLSTM_SPEC, InputSpec
from diffsense.scene import TARGET_INDEX
from tests._toy_pipeline import predictions, toy_objective

R = "range_m"
OFFSET_M = np.array([[1.0, 2.0, 3.0, 4.0], [5.0, 0.0, 0.0, 0.0], [0.0, 0.0, 6.0, 0.0]])
SQ = OFFSET_M**2 / 5.0  # [[0.2, 0.8, 1.8, 3.2], [5, 0, 0, 0], [0, 0, 7.2, 0]] [m^2]
PENALTY_M2 = 50.0
WEIGHTS = [(1.0, 1.0, 1.0), (1.0, 0.0, 1.0)]  # all real; variant 1 padding (scenario 1 then empty)


class Replay(eqx.Module):
    """A predictor that predicts `out` [B, F, 2] whatever its inputs."""

    out: jax.Array
    spec: InputSpec = eqx.field(static=True, default=CSLSTM_SPEC)

    def __call__(self, inputs):
        return self.out


@pytest.fixture(scope="module")
def tracked():
    return toy_objective(n=3, instants=4, question="tracked", miss_penalty_m2=PENALTY_M2)


@pytest.fixture(scope="module")
def by_hand(tracked):
    """`tracked` with the hand-made errors: prediction minus ground-truth-input prediction = offset."""
    pred = tracked.data.gt_pred
    offset = np.zeros(pred.shape)
    for n in range(3):
        offset[n, :, :5, n % 2] = OFFSET_M[n][:, None]
    return eqx.tree_at(lambda o: (o.predictor, o.data.gt_pred), tracked,
                       (Replay(pred.reshape(-1, *pred.shape[2:])), pred - offset))


def _weighted(E, weight):
    return eqx.tree_at(lambda o: o.data.weight, E, jnp.asarray(weight, E.dtype))


_hard = eqx.filter_jit(lambda o, r: o.hard({R: r}))
_e2_and_grad = eqx.filter_jit(lambda o, r: jax.value_and_grad(lambda x: o.e2({R: x}))(r))


def hard(E, r):
    return jax.tree.map(np.asarray, _hard(E, jnp.asarray(r)))


def soft(E, r):
    value, grad = _e2_and_grad(E, jnp.asarray(r))
    return float(value), float(grad)


def _j(q, weight):
    """J of the tracked question from tracked probabilities q [N, I] and the hand-made errors."""
    w = np.asarray(weight)[:, None] * np.ones_like(q)
    seen = np.sum(w * q)
    return np.sum(w * q * SQ) / (1.0 + seen) + PENALTY_M2 * (1.0 - seen / np.sum(w))


def _windows(E, p):
    """The target's detections over each instant's history window: the 31 frames up to and
    including the instant's (16 points 2 frames apart at 10 Hz), [N, I, 31]."""
    return np.stack([[p[n, f - 30: f + 1, TARGET_INDEX] for f in E.frames] for n in range(p.shape[0])])


@pytest.mark.parametrize("weight, expected", [(WEIGHTS[0], 18.2 / 12), (WEIGHTS[1], 13.2 / 8)])
def test_eq12_is_the_weighted_mean_over_instants_of_the_squared_error(by_hand, weight, expected):
    E = _weighted(dataclasses.replace(by_hand, question="eq12"), weight)
    for r in (0.5, 1000.0):  # whatever the sensor tracks: coverage plays no part in Eq. 12
        h = hard(E, r)
        assert float(h.e2) == float(h.objective) == pytest.approx(expected, rel=1e-12)
        assert soft(E, r)[0] == pytest.approx(expected, rel=1e-12)
        assert float(E({R: r}, mode="hard")) == pytest.approx(np.sqrt(expected), rel=1e-12)


@pytest.mark.parametrize("weight", WEIGHTS)
def test_hard_tracked_counts_an_instant_seen_once_in_its_window(by_hand, weight):
    """Hard: an instant is tracked if its target was detected at least once in the window (not
    only if throughout); the coverage classes are at the instant, in the window, throughout."""
    E = _weighted(by_hand, weight)
    for r in (26.0, 30.0, 34.0):  # somewhere the target is seen only part of a window
        h = hard(E, r)
        window = _windows(E, h.p_detect)
        classes = np.stack([window[..., -1], window.max(axis=-1), window.min(axis=-1)], axis=-1)
        np.testing.assert_array_equal(h.coverage, classes)
        if np.array_equal(classes[..., 1], classes[..., 2]):
            continue
        assert float(h.objective) == pytest.approx(_j(classes[..., 1], weight), rel=1e-12)
        assert tracked_summary(h, weight, PENALTY_M2)["J_m2"] == pytest.approx(float(h.objective), rel=1e-12)
        return
    pytest.fail("no range tried sees the target only part of a window")


@pytest.mark.parametrize("weight", WEIGHTS)
def test_soft_tracked_weighs_each_instant_by_its_probability_of_a_track(by_hand, weight):
    E = _weighted(by_hand, weight)
    p = np.asarray(E.detections({R: 30.0}, "soft").p_detect)
    q = 1.0 - np.prod(1.0 - _windows(E, p), axis=-1)
    assert np.any((q > 0.01) & (q < 0.99))  # some instants tracked with a fractional probability
    assert soft(E, 30.0)[0] == pytest.approx(_j(q, weight), rel=1e-12)


def test_every_instant_tracked_costs_no_penalty_and_one_pseudo_instant(by_hand):
    h = hard(by_hand, 1000.0)
    assert np.all(h.coverage == 1.0)
    assert float(h.objective) == pytest.approx(SQ.sum() / 13.0, rel=1e-12)  # 12 instants + 1 of zero error
    assert float(h.objective) == pytest.approx(float(h.e2) * 12 / 13, rel=1e-12)


@pytest.mark.parametrize("r", [0.01, 1000.0])  # never detected; always detected (p exactly 1)
def test_tracked_question_is_finite_at_the_extremes(tracked, r):
    value, grad = soft(tracked, r)
    assert np.isfinite(value) and np.isfinite(grad)
    h = hard(tracked, r)
    summary = tracked_summary(h, np.asarray(tracked.data.weight), PENALTY_M2)
    np.testing.assert_allclose(summary["J_m2"], float(h.objective), rtol=1e-12)
    if r < 1:
        assert summary["missed_share"] == 1.0 and float(h.objective) == PENALTY_M2
        assert PENALTY_M2 <= value < PENALTY_M2 + 10.0  # a ~2e-4 chance of a track per instant
    else:
        assert summary["missed_share"] == 0.0 and value < PENALTY_M2


@pytest.mark.parametrize("weight", WEIGHTS)
def test_hard_evaluation_against_a_loop_by_loop_recomputation(tracked, weight):
    """Every error the hard evaluation reports, from the objective's own data with numpy; with
    variant 1 as padding (weight 0), E^2 is variants 0 and 2's, and scenario 1 reports 0, not NaN.
    Per scenario the RMSE against the true future is the root of the mean over its variants."""
    E = _weighted(dataclasses.replace(tracked, question="eq12"), weight)
    h = hard(E, 30.0)
    pred = np.asarray(eqx.filter_jit(predictions)(E, E.detections({R: 30.0}, "hard")))
    gt, fut = np.asarray(E.data.gt_pred), np.asarray(E.data.true_fut)
    n_var, n_inst, n_step = gt.shape[:3]
    sq_instant = np.zeros((n_var, n_inst))
    sq_true_gt, sq_true_sensor = np.zeros((n_var, n_inst, n_step)), np.zeros((n_var, n_inst, n_step))
    for n in range(n_var):
        for i in range(n_inst):
            for k in range(n_step):
                dx, dy = pred[n, i, k] - gt[n, i, k]
                sq_instant[n, i] += (dx * dx + dy * dy) / n_step
                sq_true_gt[n, i, k] = ((gt[n, i, k] - fut[n, i, k]) ** 2).sum()
                sq_true_sensor[n, i, k] = ((pred[n, i, k] - fut[n, i, k]) ** 2).sum()
    assert sq_instant.max() > 0.0  # the sensor at 30 m misses something
    np.testing.assert_allclose(h.sq_instant, sq_instant, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(h.sq_true_gt, sq_true_gt, rtol=1e-12)
    np.testing.assert_allclose(h.sq_true_sensor, sq_true_sensor, rtol=1e-12)
    real = [n for n in range(n_var) if weight[n]]
    e2 = sq_instant[real].mean()
    assert abs(sq_instant.mean() - sq_instant[[0, 2]].mean()) > 1e-3 * e2  # the weights matter
    np.testing.assert_allclose([h.e2, h.objective], [e2, e2], rtol=1e-10)
    np.testing.assert_allclose(h.sq_error, ((pred - gt) ** 2).sum(axis=-1).mean(axis=1), rtol=1e-10, atol=1e-12)
    assert list(np.asarray(E.data.scenario)) == [0, 1, 0]
    for sq_true, rmse in ((sq_true_gt, h.rmse_gt), (sq_true_sensor, h.rmse_sensor)):
        m = sq_true.mean(axis=1)  # [N, F]: each variant's mean over instants
        assert np.all(m[0] != m[2])  # the two variants of scenario 0 differ: their mean is neither
        np.testing.assert_allclose(rmse[0], np.sqrt((m[0] + m[2]) / 2), rtol=1e-12)
        np.testing.assert_allclose(rmse[1], np.sqrt(m[1]) * weight[1], rtol=1e-12)
