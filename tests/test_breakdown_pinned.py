"""E's breakdown and the predictor's domain guard, pinned to sums written out by hand on small
hand-built evaluations (no program is compiled): which instants each part weighs, by how much,
and where the guard draws its line."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from diffsense.metrics._breakdown import _rms, breakdown, tracked_summary
from diffsense.study._domain import DOMAIN_FACTOR, domain_check, domain_note

# Three variants of two scenarios ("a": variants 0 and 2, "b": variant 1), two instants each.
SCENARIO = np.array([0, 1, 0])
WEIGHT = np.array([1.0, 2.0, 3.0])
SQ = np.array([[4.0, 16.0], [1.0, 9.0], [25.0, 36.0]])  # [N, I] squared error per instant [m^2]
# [N, I, 3]: seen at the instant, in the history window, throughout it (a subset of in_window).
COVERAGE = np.array([[[1, 1, 1], [0, 1, 0]],
                     [[0, 0, 0], [1, 1, 1]],
                     [[0, 1, 0], [0, 0, 0]]], dtype=float)


def _hard(**extra):
    f = 2
    sq_error = np.array([[1.0, 4.0], [9.0, 16.0], [0.25, 1.0]])  # [N, F]
    gt = np.arange(3 * 2 * f, dtype=float).reshape(3, 2, f)  # [N, I, F]
    return SimpleNamespace(sq_instant=SQ, coverage=COVERAGE, sq_error=sq_error, sq_true_gt=gt,
                           sq_true_sensor=2.0 * gt + 1.0, **extra)


def _wrms(pairs):
    """sqrt(sum w x sq / sum w) over (w, sq) pairs, written out."""
    return math.sqrt(sum(w * s for w, s in pairs) / sum(w for w, _ in pairs))


def test_rms_weighs_by_instant_and_is_nan_without_weight():
    assert _rms(np.array([1.0, 9.0]), np.array([3.0, 1.0])) == pytest.approx(math.sqrt(3.0), rel=1e-15)
    assert math.isnan(_rms(np.array([1.0]), np.array([0.0])))
    assert _rms(np.array([-1e-300]), np.array([1.0])) == 0.0  # never the root of a negative


def test_pooled_and_per_scenario_e_weigh_every_instant_by_its_variant():
    b = breakdown(_hard(), SCENARIO, WEIGHT, ("a", "b"), (0.5, 1.0))
    every = [(WEIGHT[n], SQ[n, i]) for n in range(3) for i in range(2)]
    assert b["E_hard"] == pytest.approx(_wrms(every), rel=1e-14)
    a = [(WEIGHT[n], SQ[n, i]) for n in (0, 2) for i in range(2)]
    assert b["by_scenario"]["a"]["E_hard"] == pytest.approx(_wrms(a), rel=1e-14)
    assert b["by_scenario"]["b"]["E_hard"] == pytest.approx(math.sqrt(5.0), rel=1e-14)
    assert list(b["by_scenario"]) == ["a", "b"]


def test_coverage_shares_and_parts():
    b = breakdown(_hard(), SCENARIO, WEIGHT, ("a", "b"), (0.5, 1.0))
    cov = b["coverage"]  # weights sum to 12 over the instants (two per variant)
    # seen at the instant: (0,0) w1, (1,1) w2 -> 3 / 12; in the window: (0,0), (0,1), (1,1), (2,0)
    # -> 1 + 1 + 2 + 3 = 7 / 12; throughout: (0,0), (1,1) -> 3 / 12.
    assert (cov["at_instant"], cov["in_window"], cov["throughout"]) == pytest.approx((3 / 12, 7 / 12, 3 / 12))
    parts = cov["parts"]
    assert list(parts) == ["throughout", "partly", "never"]
    assert parts["throughout"]["share"] == pytest.approx(3 / 12)
    assert parts["throughout"]["E_hard"] == pytest.approx(_wrms([(1.0, 4.0), (2.0, 9.0)]), rel=1e-14)
    assert parts["partly"]["share"] == pytest.approx(4 / 12)  # (0,1) w1 and (2,0) w3
    assert parts["partly"]["E_hard"] == pytest.approx(_wrms([(1.0, 16.0), (3.0, 25.0)]), rel=1e-14)
    assert parts["never"]["share"] == pytest.approx(5 / 12)  # (1,0) w2 and (2,1) w3
    assert parts["never"]["E_hard"] == pytest.approx(_wrms([(2.0, 1.0), (3.0, 36.0)]), rel=1e-14)
    # Scenario b alone: one instant never seen, one throughout: no "partly" part, E None there.
    b_cov = b["by_scenario"]["b"]["coverage"]
    assert b_cov["parts"]["partly"] == {"share": 0.0, "E_hard": None}
    assert b_cov["parts"]["never"] == {"share": 0.5, "E_hard": 1.0}
    assert (b_cov["at_instant"], b_cov["in_window"], b_cov["throughout"]) == (0.5, 0.5, 0.5)


def test_tracked_part_of_each_scenario():
    b = breakdown(_hard(), SCENARIO, WEIGHT, ("a", "b"), (0.5, 1.0))
    a = b["by_scenario"]["a"]  # tracked (in window): (0,0) w1 sq4, (0,1) w1 sq16, (2,0) w3 sq25
    assert a["E_tracked"] == pytest.approx(math.sqrt((4 + 16 + 75) / 5.0), rel=1e-14)
    assert a["missed_share"] == pytest.approx(1 - 5 / 8)
    bb = b["by_scenario"]["b"]
    assert bb["E_tracked"] == pytest.approx(3.0) and bb["missed_share"] == pytest.approx(0.5)


def test_per_horizon_rows():
    b = breakdown(_hard(), SCENARIO, WEIGHT, ("a", "b"), (0.5, 1.0))
    h = b["by_horizon"]
    assert h["t_s"] == [0.5, 1.0] and all(type(t) is float for t in h["t_s"])
    # Eq. 12 per step: variants weighed once each (sq_error is already over the instants).
    assert h["E_hard"] == pytest.approx([math.sqrt((1 + 18 + 0.75) / 6), math.sqrt((4 + 32 + 3) / 6)])
    gt = _hard().sq_true_gt
    for f in range(2):
        pairs = [(WEIGHT[n], gt[n, i, f]) for n in range(3) for i in range(2)]
        assert h["rmse_true_gt"][f] == pytest.approx(_wrms(pairs), rel=1e-14)
        pairs = [(WEIGHT[n], 2 * gt[n, i, f] + 1) for n in range(3) for i in range(2)]
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
    never = SimpleNamespace(sq_instant=SQ, coverage=np.zeros_like(COVERAGE))
    n = tracked_summary(never, WEIGHT, 7.0)
    assert n["E_tracked"] is None and n["missed_share"] == 1.0 and n["J_m2"] == 7.0


def test_one_tracked_instant_of_unit_weight_has_its_e():
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


def _objective(gt_minus_true, rate_hz=2.0, future_points=5, weight=(1.0, 1.0, 2.0), scenario=(0, 0, 1)):
    """A stand-in for an objective: the domain guard reads its data, spec and scenario names."""
    n, i = len(weight), 2
    true = np.broadcast_to(np.array([100.0, -3.0]), (n, i, future_points, 2))  # the true future [m]
    gt = true + np.asarray(gt_minus_true, float)
    data = SimpleNamespace(gt_pred=gt, true_fut=true, weight=np.asarray(weight), scenario=np.asarray(scenario))
    return SimpleNamespace(data=data, spec=SimpleNamespace(rate_hz=rate_hz, future_points=future_points),
                           scenario_names=("slow", "fast"))


def test_domain_rmse_at_each_whole_second():
    # Error grows with the step: 1 m per step in x, scenario "fast" 10 x as large.
    steps = np.arange(5, dtype=float)[None, None, :, None] * np.array([1.0, 0.0])
    err = np.concatenate([steps, steps, 10 * steps], axis=0)[:, [0, 0]]  # [3, 2, 5, 2]
    check = domain_check(_objective(err), None)
    # 2 Hz: whole seconds are steps 1 and 3 (0.5 s each); 5 points hold 2 whole seconds.
    assert check["scenarios"]["slow"]["rmse_gt_m"] == pytest.approx([1.0, 3.0])
    assert check["scenarios"]["fast"]["rmse_gt_m"] == pytest.approx([10.0, 30.0])
    assert check["outside"] == [] and check["scenarios"]["slow"]["inside"] is None
    assert check["factor"] == DOMAIN_FACTOR == 2.0 and check["validation_rmse_m"] is None
    # A rate of 2.6 Hz rounds to 3 steps per second: steps 2 and 5 of 7.
    ramp = np.broadcast_to(np.arange(7.0)[None, None, :, None] * np.array([1.0, 0.0]), (3, 2, 7, 2))
    check = domain_check(_objective(ramp, rate_hz=2.6, future_points=7), None)
    assert check["scenarios"]["slow"]["rmse_gt_m"] == pytest.approx([2.0, 5.0])


def test_domain_weighs_variants_and_averages_instants():
    err = np.zeros((3, 2, 2, 2))
    err[0, 0, 1] = (3.0, 4.0)  # variant 0 (weight 1), one of its two instants: sq 25
    err[1, :, 1] = (0.0, 1.0)  # variant 1 (weight 1), both instants: sq 1
    check = domain_check(_objective(err, rate_hz=2.0, future_points=2), None)
    assert check["scenarios"]["slow"]["rmse_gt_m"] == pytest.approx([math.sqrt((25 + 1 + 1) / 4)])
    assert check["scenarios"]["fast"]["rmse_gt_m"] == [0.0]


def test_domain_sums_float32_in_float64():
    big = float(2**24)  # 2^24 + 1 is 2^24 in float32
    err = np.zeros((3, 2, 2, 2))
    err[0, :, 1, 0], err[1:, :, 1, 0] = 2.0, 1.0  # the heavy variant 2 m off, the others 1 m
    obj = _objective(err, future_points=2, weight=(big, 1.0, 1.0))  # "slow": variants 0 and 1
    obj.data.gt_pred, obj.data.true_fut = obj.data.gt_pred.astype(np.float32), obj.data.true_fut.astype(np.float32)
    obj.data.weight = obj.data.weight.astype(np.float32)
    rmse = domain_check(obj, None)["scenarios"]["slow"]["rmse_gt_m"]
    assert rmse == pytest.approx([math.sqrt((4 * big + 1) / (big + 1))], rel=1e-15)


def test_the_guard_draws_its_line_at_twice_the_validation_rmse():
    # 1, 3 and 5 m at the whole seconds (steps 1, 3, 5 of 6 at 2 Hz), against 0.5, 1.5, 2.5 m.
    err = np.broadcast_to(np.arange(6.0)[None, None, :, None] * np.array([1.0, 0.0]), (3, 2, 6, 2))
    inside = domain_check(_objective(err, future_points=6), (0.5, 1.5, 2.5))  # exactly 2x: inside
    assert inside["scenarios"]["fast"]["rmse_gt_m"] == pytest.approx([1.0, 3.0, 5.0])
    assert inside["outside"] == [] and inside["scenarios"]["fast"]["inside"] is True
    assert domain_note(inside) is None
    below = domain_check(_objective(err, future_points=6), (0.5, math.nextafter(1.5, 0.0), 2.5))
    assert below["outside"] == ["slow", "fast"] and below["scenarios"]["slow"]["inside"] is False
    assert domain_note(below) == (
        "outside the predictor's domain: slow (5.0 m at 3 s), fast (5.0 m at 3 s): even from "
        "ground-truth histories its prediction is more than 2x its validation RMSE off the true "
        "future, so E there says little about the sensor")
