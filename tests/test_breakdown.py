"""E broken down (by scenario, coverage and horizon) adds up, and the "tracked" question is safe."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.metrics._breakdown import breakdown, tracked_summary
from diffsense.tracks import build_inputs
from tests._toy_pipeline import toy_objective

R = "range_m"


@pytest.fixture(scope="module")
def objective():
    return toy_objective(n=4, fill="hold")  # scenarios 0, 1, 0, 1 (toy_scenes)


def _hard(E, r):
    return jax.tree.map(np.asarray, eqx.filter_jit(lambda E: E.hard({R: r}))(E))


@pytest.mark.parametrize("r", [20.0, 38.0, 300.0])
def test_parts_add_up_to_the_pooled_e2(objective, r):
    h = _hard(objective, r)
    b = breakdown(h, np.asarray(objective.data.scenario), np.asarray(objective.data.weight),
                  objective.scenario_names, objective.spec.horizon_s())
    e2 = float(h.e2)
    np.testing.assert_allclose(b["E_hard"] ** 2, e2, rtol=1e-12)
    # By scenario: every scenario has 2 of the 4 variants and the same instants -> share 1/2.
    by_scenario = sum(0.5 * part["E_hard"] ** 2 for part in b["by_scenario"].values())
    np.testing.assert_allclose(by_scenario, e2, rtol=1e-9, atol=1e-12)
    parts = b["coverage"]["parts"]
    assert sum(p["share"] for p in parts.values()) == pytest.approx(1.0, abs=1e-12)
    by_coverage = sum(p["share"] * (p["E_hard"] or 0.0) ** 2 for p in parts.values())
    np.testing.assert_allclose(by_coverage, e2, rtol=1e-9, atol=1e-12)
    cov = b["coverage"]
    assert 0 <= cov["throughout"] <= cov["in_window"] <= 1 and cov["at_instant"] <= cov["in_window"]


def test_blind_and_far_sighted_coverage(objective):
    blind = breakdown(_hard(objective, 0.01), np.asarray(objective.data.scenario),
                      np.asarray(objective.data.weight), objective.scenario_names, objective.spec.horizon_s())
    assert blind["coverage"]["in_window"] == 0.0 and blind["coverage"]["parts"]["never"]["share"] == 1.0
    far = breakdown(_hard(objective, 1000.0), np.asarray(objective.data.scenario),
                    np.asarray(objective.data.weight), objective.scenario_names, objective.spec.horizon_s())
    assert far["coverage"]["throughout"] == 1.0


def test_per_horizon_rmse_matches_a_numpy_recomputation(objective):
    r = 38.0
    h = _hard(objective, r)
    b = breakdown(h, np.asarray(objective.data.scenario), np.asarray(objective.data.weight),
                  objective.scenario_names, objective.spec.horizon_s())
    # Independent path: inputs built scene by scene with the public tracks function, the
    # predictor called on them, errors summed in plain loops.
    det = eqx.filter_jit(lambda E: E.detections({R: r}, "hard"))(objective)
    frames = jnp.asarray(objective.frames)
    gt_fut, true_fut = np.asarray(objective.data.gt_pred), np.asarray(objective.data.true_fut)
    n, i, f, _ = gt_fut.shape
    sq_sensor, sq_gt, sq_eq12 = np.zeros(f), np.zeros(f), np.zeros(f)
    for v in range(n):
        scene = jax.tree.map(lambda a: a[v], objective.data.scenes)
        d = jax.tree.map(lambda a: a[v], det)
        pred = np.asarray(objective.predictor(build_inputs(scene, d, frames, objective.fill)))
        for k in range(i):
            for step in range(f):
                sq_sensor[step] += np.sum((pred[k, step] - true_fut[v, k, step]) ** 2)
                sq_gt[step] += np.sum((gt_fut[v, k, step] - true_fut[v, k, step]) ** 2)
                sq_eq12[step] += np.sum((pred[k, step] - gt_fut[v, k, step]) ** 2)
    count = n * i
    np.testing.assert_allclose(b["by_horizon"]["rmse_true_sensor"], np.sqrt(sq_sensor / count), rtol=1e-9)
    np.testing.assert_allclose(b["by_horizon"]["rmse_true_gt"], np.sqrt(sq_gt / count), rtol=1e-9)
    np.testing.assert_allclose(b["by_horizon"]["E_hard"], np.sqrt(sq_eq12 / count), rtol=1e-9)
    np.testing.assert_allclose(b["by_horizon"]["t_s"], 0.2 * np.arange(1, 26), rtol=1e-12)


@pytest.mark.parametrize("r", [0.01, 1000.0])  # never detected; always detected
def test_tracked_question_is_finite_at_the_extremes(r):
    E = toy_objective(n=2, instants=4, fill="zero", question="tracked", miss_penalty_m2=50.0)
    value, grad = eqx.filter_jit(jax.value_and_grad(lambda x, E: E.e2({R: x})))(r, E)
    assert np.isfinite(float(value)) and np.isfinite(float(grad))
    hard = _hard(E, r)
    summary = tracked_summary(hard, np.asarray(E.data.weight), 50.0)
    np.testing.assert_allclose(summary["J_m2"], float(hard.objective), rtol=1e-12)
    if r < 1:
        assert summary["missed_share"] == 1.0 and summary["J_m2"] == pytest.approx(50.0)
        # Soft: each of the 8 instants tracked with probability ~2e-4 (31 frames at p ~ 6e-6), so
        # the error term is at most ~1.6e-3 x the ~5,250 m^2 of an untracked instant: ~8 m^2.
        assert 50.0 <= float(value) < 60.0
    else:
        assert summary["missed_share"] == 0.0
        assert float(value) < 50.0


def test_tracked_differs_from_eq12_only_by_its_question():
    eq12 = toy_objective(n=2, instants=4, fill="zero")
    tracked = toy_objective(n=2, instants=4, fill="zero", question="tracked", miss_penalty_m2=0.0)
    far = {R: 1000.0}  # every one of the 2 x 4 instants tracked: both ask the same question, but
    # "tracked" divides by its 8 instants plus the one pseudo-instant of zero error.
    np.testing.assert_allclose(float(tracked(far, mode="hard")) ** 2, float(eq12(far, mode="hard")) ** 2 * 8 / 9,
                               rtol=1e-12)
