"""E broken down by scenario, coverage and horizon (`diffsense.metrics.breakdown`) and the tracked
question's summary (`tracked_summary`): sums written out by hand on small hand-built evaluations,
and on the toy objective's own evaluations the parts adding up to the pooled E^2."""

from __future__ import annotations

import math
from types import SimpleNamespace

import equinox as eqx
import jax
import numpy as np
import pytest

from diffsense.metrics import COVERAGE_PARTS, breakdown, coverage_parts, tracked_summary
from tests._toy_pipeline import predictions, toy_objective

# Three variants of two scenarios ("a": variants 0 and 2, "b": variant 1), two instants each.
SCENARIO = np.array([0, 1, 0])
WEIGHT = np.array([1.0, 2.0, 3.0])
SQ = np.array([[4.0, 16.0], [1.0, 9.0], [25.0, 36.0]])  # [N, I] squared error per instant [m^2]
# [N, I, 3]: seen at the instant, in the history window, throughout it (a subset of in_window).
COVERAGE = np.array([[[1, 1, 1], [0, 1, 0]],
                     [[0, 0, 0], [1, 1, 1]],
                     [[0, 1, 0], [0, 0, 0]]], dtype=float)
GT = np.arange(12, dtype=float).reshape(3, 2, 2)  # [N, I, F] squared error against the true future


def _hard(**extra):
    return SimpleNamespace(sq_instant=SQ, coverage=COVERAGE, sq_error=np.array([[1.0, 4.0], [9.0, 16.0], [0.25, 1.0]]),
                           sq_true_gt=GT, sq_true_sensor=2.0 * GT + 1.0, **extra)


def _wrms(pairs):
    """sqrt(sum w x sq / sum w) over (w, sq) pairs, written out."""
    return math.sqrt(sum(w * s for w, s in pairs) / sum(w for w, _ in pairs))


@pytest.fixture(scope="module")
def hand():
    return breakdown(_hard(), SCENARIO, WEIGHT, ("a", "b"), (0.5, 1.0))


def test_pooled_and_per_scenario_e_weigh_every_instant_by_its_variant(hand):
    assert hand["E_hard"] == pytest.approx(_wrms([(WEIGHT[n], SQ[n, i]) for n in range(3) for i in range(2)]), rel=1e-14)
    a = [(WEIGHT[n], SQ[n, i]) for n in (0, 2) for i in range(2)]
    assert hand["by_scenario"]["a"]["E_hard"] == pytest.approx(_wrms(a), rel=1e-14)
    assert hand["by_scenario"]["b"]["E_hard"] == pytest.approx(math.sqrt(5.0), rel=1e-14)
    assert list(hand["by_scenario"]) == ["a", "b"]
    # never the root of a negative (a rounding below zero): 0
    tiny = SimpleNamespace(**{**vars(_hard()), "sq_instant": np.full((3, 2), -1e-300), "coverage": 0.0 * COVERAGE})
    assert breakdown(tiny, SCENARIO, WEIGHT, ("a", "b"), (0.5, 1.0))["E_hard"] == 0.0


def test_coverage_shares_and_parts(hand):
    cov = hand["coverage"]  # weights sum to 12 over the instants (two per variant)
    # seen at the instant: (0,0) w1, (1,1) w2 -> 3 / 12; in the window: (0,0), (0,1), (1,1), (2,0)
    # -> 1 + 1 + 2 + 3 = 7 / 12; throughout: (0,0), (1,1) -> 3 / 12.
    assert (cov["at_instant"], cov["in_window"], cov["throughout"]) == pytest.approx((3 / 12, 7 / 12, 3 / 12))
    parts = cov["parts"]
    assert tuple(parts) == COVERAGE_PARTS == ("throughout", "partly", "never")
    assert parts["throughout"]["share"] == pytest.approx(3 / 12)
    assert parts["throughout"]["E_hard"] == pytest.approx(_wrms([(1.0, 4.0), (2.0, 9.0)]), rel=1e-14)
    assert parts["partly"]["share"] == pytest.approx(4 / 12)  # (0,1) w1 and (2,0) w3
    assert parts["partly"]["E_hard"] == pytest.approx(_wrms([(1.0, 16.0), (3.0, 25.0)]), rel=1e-14)
    assert parts["never"]["share"] == pytest.approx(5 / 12)  # (1,0) w2 and (2,1) w3
    assert parts["never"]["E_hard"] == pytest.approx(_wrms([(2.0, 1.0), (3.0, 36.0)]), rel=1e-14)
    # Scenario b alone: one instant never seen, one throughout: no "partly" part, E None there.
    b_cov = hand["by_scenario"]["b"]["coverage"]
    assert b_cov["parts"]["partly"] == {"share": 0.0, "E_hard": None}
    assert b_cov["parts"]["never"] == {"share": 0.5, "E_hard": 1.0}
    assert (b_cov["at_instant"], b_cov["in_window"], b_cov["throughout"]) == (0.5, 0.5, 0.5)
    # the partition itself, of windows seen throughout, once and never
    split = coverage_parts(np.array([[1.0, 1.0, 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]]))
    assert {k: v.tolist() for k, v in split.items()} == {
        "throughout": [True, False, False], "partly": [False, True, False], "never": [False, False, True]}


def test_tracked_part_of_each_scenario(hand):
    a = hand["by_scenario"]["a"]  # tracked (in window): (0,0) w1 sq4, (0,1) w1 sq16, (2,0) w3 sq25
    assert a["E_tracked"] == pytest.approx(math.sqrt((4 + 16 + 75) / 5.0), rel=1e-14)
    assert a["missed_share"] == pytest.approx(1 - 5 / 8)
    assert hand["by_scenario"]["b"]["E_tracked"] == pytest.approx(3.0)
    assert hand["by_scenario"]["b"]["missed_share"] == pytest.approx(0.5)


def test_per_horizon_rows(hand):
    h = hand["by_horizon"]
    assert h["t_s"] == [0.5, 1.0] and all(type(t) is float for t in h["t_s"])
    # Eq. 12 per step: variants weighed once each (sq_error is already over the instants).
    assert h["E_hard"] == pytest.approx([math.sqrt((1 + 18 + 0.75) / 6), math.sqrt((4 + 32 + 3) / 6)])
    for f in range(2):
        pairs = [(WEIGHT[n], GT[n, i, f]) for n in range(3) for i in range(2)]
        assert h["rmse_true_gt"][f] == pytest.approx(_wrms(pairs), rel=1e-14)
        pairs = [(WEIGHT[n], 2 * GT[n, i, f] + 1) for n in range(3) for i in range(2)]
        assert h["rmse_true_sensor"][f] == pytest.approx(_wrms(pairs), rel=1e-14)


def test_tracked_summary_is_j_of_the_tracked_question():
    s = tracked_summary(_hard(), WEIGHT, 100.0)
    seen = 1 + 1 + 2 + 3  # weights of the tracked instants
    error = 1 * 4 + 1 * 16 + 2 * 9 + 3 * 25
    assert s["E_tracked"] == pytest.approx(math.sqrt(error / seen), rel=1e-14)
    assert s["missed_share"] == pytest.approx(5 / 12)
    # One pseudo-instant of zero error in the denominator, and the price of the missed share.
    assert s["J_m2"] == pytest.approx(error / (1 + seen) + 100.0 * 5 / 12, rel=1e-14)
    assert s["miss_penalty_m2"] == 100.0
    never = tracked_summary(SimpleNamespace(sq_instant=SQ, coverage=np.zeros_like(COVERAGE)), WEIGHT, 7.0)
    assert never["E_tracked"] is None and never["missed_share"] == 1.0 and never["J_m2"] == 7.0
    one = SimpleNamespace(sq_instant=np.array([[9.0, 4.0]]), coverage=np.array([[[1, 1, 1], [0, 0, 0]]], float))
    s = tracked_summary(one, np.array([1.0]), 0.0)
    assert s["E_tracked"] == 3.0 and s["missed_share"] == 0.5 and s["J_m2"] == 4.5


def test_float32_inputs_are_summed_in_float64():
    # 2^24 + 1 is 2^24 in float32: summed there, the two unit weights (or errors) would vanish.
    big = float(2**24)
    weight = np.array([big, 1.0, 1.0], np.float32)
    sq_error = np.array([[big], [1.0], [1.0]], np.float32)
    sq_true = np.array([[[big]], [[1.0]], [[1.0]]], np.float32)
    hard = SimpleNamespace(sq_instant=np.ones((3, 1), np.float32), coverage=np.ones((3, 1, 3), np.float32),
                           sq_error=sq_error, sq_true_gt=sq_true, sq_true_sensor=sq_true)
    b = breakdown(hard, np.array([0, 0, 0]), weight, ("a",), (0.2,))
    exact = math.sqrt((big * big + 2.0) / (big + 2.0))
    for key in ("E_hard", "rmse_true_gt", "rmse_true_sensor"):
        assert b["by_horizon"][key][0] == pytest.approx(exact, rel=1e-15), key
    untracked = SimpleNamespace(sq_instant=hard.sq_instant, coverage=np.zeros((3, 1, 3), np.float32))
    hard.coverage[0, 0, 1] = 0.0  # the heavy variant untracked: 2 of 2^24 + 2 tracked
    assert tracked_summary(hard, weight, 0.0)["missed_share"] == 1.0 - 2.0 / (big + 2.0)  # not 1 - 2 / 2^24
    assert tracked_summary(untracked, weight, 0.0)["missed_share"] == 1.0


@pytest.fixture(scope="module")
def objective():
    return toy_objective(n=4, fill="hold")  # scenarios 0, 1, 0, 1 (toy_scenes)


def _breakdown(E, r):
    h = jax.tree.map(np.asarray, eqx.filter_jit(lambda E: E.hard({"range_m": r}))(E))
    return h, breakdown(h, np.asarray(E.data.scenario), np.asarray(E.data.weight), E.scenario_names, E.spec.horizon_s())


@pytest.mark.parametrize("r", [20.0, 38.0, 300.0])
def test_parts_add_up_to_the_pooled_e2(objective, r):
    h, b = _breakdown(objective, r)
    e2 = float(h.e2)
    np.testing.assert_allclose(b["E_hard"] ** 2, e2, rtol=1e-12)
    # By scenario: every scenario has 2 of the 4 variants and the same instants -> share 1/2.
    np.testing.assert_allclose(sum(0.5 * p["E_hard"] ** 2 for p in b["by_scenario"].values()), e2, rtol=1e-9, atol=1e-12)
    parts = b["coverage"]["parts"]
    assert sum(p["share"] for p in parts.values()) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(sum(p["share"] * (p["E_hard"] or 0.0) ** 2 for p in parts.values()), e2,
                               rtol=1e-9, atol=1e-12)
    cov = b["coverage"]
    assert 0 <= cov["throughout"] <= cov["in_window"] <= 1 and cov["at_instant"] <= cov["in_window"]


def test_blind_and_far_sighted_coverage(objective):
    blind = _breakdown(objective, 0.01)[1]["coverage"]
    assert blind["in_window"] == 0.0 and blind["parts"]["never"]["share"] == 1.0
    assert _breakdown(objective, 1000.0)[1]["coverage"]["throughout"] == 1.0


def test_per_horizon_rmse_matches_a_numpy_recomputation(objective):
    _, b = _breakdown(objective, 38.0)
    det = eqx.filter_jit(lambda E: E.detections({"range_m": 38.0}, "hard"))(objective)
    pred = np.asarray(eqx.filter_jit(predictions)(objective, det))  # the public tracks functions' path
    gt_fut, true_fut = np.asarray(objective.data.gt_pred), np.asarray(objective.data.true_fut)
    count = gt_fut.shape[0] * gt_fut.shape[1]
    for key, a, b_ in (("rmse_true_sensor", pred, true_fut), ("rmse_true_gt", gt_fut, true_fut), ("E_hard", pred, gt_fut)):
        np.testing.assert_allclose(b["by_horizon"][key], np.sqrt(((a - b_) ** 2).sum(axis=(0, 1, 3)) / count), rtol=1e-9)
    np.testing.assert_allclose(b["by_horizon"]["t_s"], 0.2 * np.arange(1, 26), rtol=1e-12)
