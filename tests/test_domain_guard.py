"""The predictor's domain guard (`diffsense.study.domain_check`, `domain_note`) on hand-built
objective data (no program is compiled): the ground-truth-input RMSE at each whole second, which
instants and variants it weighs, and where it draws its line (twice the validation RMSE)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from diffsense.study import domain_check, domain_note


def _objective(gt_minus_true, rate_hz=2.0, future_points=5, weight=(1.0, 1.0, 2.0), scenario=(0, 0, 1)):
    """A stand-in for an objective: the guard reads its data, spec and scenario names."""
    n, i = len(weight), 2
    true = np.broadcast_to(np.array([100.0, -3.0]), (n, i, future_points, 2))  # the true future [m]
    data = SimpleNamespace(gt_pred=true + np.asarray(gt_minus_true, float), true_fut=true,
                           weight=np.asarray(weight), scenario=np.asarray(scenario))
    return SimpleNamespace(data=data, spec=SimpleNamespace(rate_hz=rate_hz, future_points=future_points),
                           scenario_names=("slow", "fast"))


def _ramp(points, scale=(1.0, 1.0, 10.0)):
    """An error of `scale` m per horizon step in x, per variant, at both instants: [3, 2, points, 2]."""
    steps = np.arange(points, dtype=float)[None, None, :, None] * np.array([1.0, 0.0])
    return np.broadcast_to(np.asarray(scale)[:, None, None, None] * steps, (3, 2, points, 2))


def test_rmse_at_each_whole_second():
    check = domain_check(_objective(_ramp(5)), None)
    # 2 Hz: whole seconds are steps 1 and 3 (0.5 s each); 5 points hold 2 whole seconds.
    assert check["scenarios"]["slow"]["rmse_gt_m"] == pytest.approx([1.0, 3.0])
    assert check["scenarios"]["fast"]["rmse_gt_m"] == pytest.approx([10.0, 30.0])
    assert check["outside"] == [] and check["scenarios"]["slow"]["inside"] is None
    assert check["factor"] == 2.0 and check["validation_rmse_m"] is None
    # A rate of 2.6 Hz rounds to 3 steps per second: steps 2 and 5 of 7.
    check = domain_check(_objective(_ramp(7, (1.0, 1.0, 1.0)), rate_hz=2.6, future_points=7), None)
    assert check["scenarios"]["slow"]["rmse_gt_m"] == pytest.approx([2.0, 5.0])


def test_variants_are_weighed_and_instants_averaged():
    err = np.zeros((3, 2, 2, 2))
    err[0, 0, 1] = (3.0, 4.0)  # variant 0 (weight 1), one of its two instants: sq 25
    err[1, :, 1] = (0.0, 1.0)  # variant 1 (weight 1), both instants: sq 1
    check = domain_check(_objective(err, future_points=2), None)
    assert check["scenarios"]["slow"]["rmse_gt_m"] == pytest.approx([math.sqrt((25 + 1 + 1) / 4)])
    assert check["scenarios"]["fast"]["rmse_gt_m"] == [0.0]


def test_float32_is_summed_in_float64():
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
    err = _ramp(6, (1.0, 1.0, 1.0))
    inside = domain_check(_objective(err, future_points=6), (0.5, 1.5, 2.5))  # exactly 2x: inside
    assert inside["scenarios"]["fast"]["rmse_gt_m"] == pytest.approx([1.0, 3.0, 5.0])
    assert inside["outside"] == [] and inside["scenarios"]["fast"]["inside"] is True
    assert domain_note(inside) is None
    below = domain_check(_objective(err, future_points=6), (0.5, math.nextafter(1.5, 0.0), 2.5))
    assert below["outside"] == ["slow", "fast"] and below["scenarios"]["slow"]["inside"] is False
    note = domain_note(below)  # names each scenario outside, with its error at its last whole second
    assert "slow (5.0 m at 3 s), fast (5.0 m at 3 s)" in note and "2x" in note
