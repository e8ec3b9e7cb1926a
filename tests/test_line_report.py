"""What the one-parameter main job reports beside r* (`diffsense.study._line_report`), pinned on a
stand-in evaluator whose E, dE^2/dr, hard evaluations and reference are written out here: the
curves the figures draw, the dense reference check and result.json's
"reference". Only the first-variant gather of a tiny scene is compiled."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import jax.numpy as jnp
import numpy as np
import pytest

import diffsense as ds
from diffsense.scene import ADJACENT, EGO, LEAD, TARGET, Scene
from diffsense.study._line_report import (
    curves,
    dense_check,
    reference_summary,
)


def _soft_e(r):
    return 1.0 + r * r / 100.0  # E_soft [m]; dE/dr = r / 50


class FakeEvaluator:
    """E_soft = 1 + r^2/100 (but 0 at r = 7, a rounding-negative E^2 at r = 8 and 0.5 m at 9),
    E_hard = 2 + r/1000, E_ref with minima 3 m at 12 and 3.5 m at 30, SE r/100; per-scenario RMSE rows and
    a detection timeline [N=2, T=3, V=4] that encode r."""

    def __init__(self, estimator_kind=None):
        self.taus = []
        if estimator_kind is not None:
            self.objective = SimpleNamespace(estimator_kind=estimator_kind)
        else:
            self.objective = object()

    def value_and_grad(self, r, tau):
        self.taus.append(tau)
        if r == 7.0:
            return 0.0, [5.0]
        if r == 8.0:
            return -1e-18, [5.0]
        if r == 9.0:
            return 0.25, [0.3]  # E = 0.5 m: dE/dr = 0.3 / (2 x 0.5)
        e = _soft_e(r)
        return e * e, [2.0 * e * r / 50.0]

    def e_hard(self, r):
        return 2.0 + r / 1000.0

    def hard(self, r):
        p = np.zeros((2, 3, 4))
        p[0] = r + np.arange(12.0).reshape(3, 4)  # variant 0: r + 4 t + v
        p[1] = -1.0  # another variant: never shown
        return SimpleNamespace(rmse_gt=[np.array([1.0, 2.0]), np.array([3.0, 4.0])],
                               rmse_sensor=[np.array([r, 2 * r]), np.array([3 * r, 4 * r])], p_detect=p)

    def e_reference(self, r):
        return self.reference(r).e

    def reference(self, r):
        e = min((r - 12.0) ** 2 / 10.0 + 3.0, (r - 30.0) ** 2 / 10.0 + 3.5)  # two basins
        return SimpleNamespace(e=e, e_se=r / 100.0, draws=np.zeros(32))


def _scenes():
    """Two variants of four vehicles: ego, target, an absent slot, a lead, then an adjacent one
    in the second variant only (the timeline is the first variant's)."""
    fields = {}
    for name in (f.name for f in dataclasses.fields(Scene) if f.name != "dt_s"):
        shape = (2, 5) if name in ("length_m", "width_m", "kind", "role", "present") else (2, 3, 5)
        dtype = jnp.int32 if name in ("lane", "kind", "role") else jnp.bool_ if name == "present" else jnp.float64
        fields[name] = jnp.zeros(shape, dtype)
    fields["role"] = jnp.asarray([[EGO, TARGET, ADJACENT, LEAD, ADJACENT]] * 2, jnp.int32)
    fields["present"] = jnp.asarray([[True, True, False, True, False], [True] * 5])
    return Scene(**fields, dt_s=0.1)


def _objective():
    data = SimpleNamespace(scenes=_scenes(), scenario=np.array([0, 1]), weight=np.array([1.0, 3.0]))
    return SimpleNamespace(scenario_names=("a", "b"), spec=SimpleNamespace(horizon_s=lambda: (0.2, 0.4)), data=data)


def _result(r_star=20.0, taus=(4.0, 2.0, 0.5)):
    sweep = [SimpleNamespace(r=r) for r in (10.0, 20.0, 40.0)]
    return SimpleNamespace(r_star=r_star, sweep=sweep, tau_schedule=taus, bracket=(10.0, 40.0))


def test_curves_evaluate_sweep_r_star_and_extra_points_at_the_last_temperature():
    ev = FakeEvaluator()
    c = curves(ev, _objective(), _result(r_star=25.0), 10.0, 40.0, 4, hard_only=False)
    assert c.r == (10.0, 20.0, 25.0, 30.0, 40.0)  # sweep, r*, linspace(10, 40, 4), each once, sorted
    assert set(ev.taus) == {0.5}
    assert c.E_soft == pytest.approx(tuple(_soft_e(r) for r in c.r), rel=1e-14)
    assert c.dE_dr == pytest.approx(tuple(r / 50.0 for r in c.r), rel=1e-14)
    assert c.E_hard == pytest.approx(tuple(2.0 + r / 1000.0 for r in c.r), rel=1e-15)
    assert curves(FakeEvaluator(), _objective(), _result(), 10.0, 40.0, 0, False).r == (10.0, 20.0, 40.0)
    no_schedule = FakeEvaluator()
    curves(no_schedule, _objective(), _result(taus=()), 10.0, 40.0, 0, False)
    assert set(no_schedule.taus) == {1.0}
    hard = curves(FakeEvaluator(), _objective(), _result(), 10.0, 40.0, 0, hard_only=True)  # E_soft repeats E_hard
    assert hard.E_soft == hard.E_hard == pytest.approx(tuple(2.0 + r / 1000.0 for r in (10.0, 20.0, 40.0)), rel=1e-15)
    assert hard.dE_dr == (0.0, 0.0, 0.0)


def test_a_zero_or_rounding_negative_e_has_slope_0_and_a_small_one_its_own():
    result = SimpleNamespace(r_star=7.0, sweep=[SimpleNamespace(r=8.0), SimpleNamespace(r=9.0)], tau_schedule=(1.0,))
    c = curves(FakeEvaluator(), _objective(), result, 7.0, 9.0, 0, hard_only=False)
    assert c.E_soft == (0.0, 0.0, 0.5) and c.dE_dr == pytest.approx((0.0, 0.0, 0.3), rel=1e-15)


def test_curves_horizons_and_the_first_variants_timeline():
    c = curves(FakeEvaluator(), _objective(), _result(r_star=25.0), 10.0, 40.0, 0, hard_only=False)
    np.testing.assert_array_equal(c.horizon_gt["a"], [1.0, 2.0])
    np.testing.assert_array_equal(c.horizon_gt["b"], [3.0, 4.0])
    assert list(c.horizon_sensor["b"]) == [10.0, 20.0, 40.0]  # the sweep's steps, not r*
    np.testing.assert_array_equal(c.horizon_sensor["b"][20.0], [60.0, 80.0])
    assert c.horizon_s == (0.2, 0.4) and c.dt_s == 0.1 and type(c.dt_s) is float
    # Columns: every present vehicle but the ego (1 and 3; slot 2 is absent, 4 of variant 1 only).
    assert c.timeline_roles == ("target", "lead")
    assert list(c.timeline) == [10.0, 25.0, 40.0]  # lo, r*, hi
    np.testing.assert_array_equal(c.timeline[25.0], 25.0 + np.array([[1, 3], [5, 7], [9, 11]]))


def test_the_dense_check_finds_the_best_grid_point_and_judges_r_star():
    ev = FakeEvaluator()
    d = dense_check(ev, _result(r_star=12.5), 0.0, 30.0, 5.0)  # grid 0, 5, ..., 30: best at 10
    assert (d["step"], d["evaluations"], d["objective"], d["reference_draws"]) == (5.0, 7, "reference", 32)
    assert d["r_best"] == 10.0 and d["E_ref_best"] == pytest.approx(3.4) and d["E_ref_best_se"] == 0.1
    assert d["E_ref_star"] == pytest.approx(3.025) and d["E_ref_star_se"] == 0.125
    assert d["E_ref_star_minus_best"] == pytest.approx(3.025 - 3.4)
    # E_ref on the grid: 17.4, 7.9, 3.4, 3.9, 9.4, 6.0, 3.5: the best point's basin is [0, 20].
    assert d["basin"] == [0.0, 20.0] and d["in_basin"] is True
    assert sorted(d) == sorted([  # result.json's dense_check keys (the grid's own wall time among them)
        "step", "evaluations", "wall_s", "objective", "reference_draws", "r_best", "E_ref_best", "E_ref_best_se",
        "E_ref_star", "E_ref_star_se", "basin", "in_basin", "E_ref_star_minus_best", "verdict"])
    # Within half a spacing (2.5) of the basin r* is in it; past that, in the other basin.
    assert dense_check(ev, _result(r_star=22.5), 0.0, 30.0, 5.0)["in_basin"] is True
    far = dense_check(ev, _result(r_star=27.0), 0.0, 30.0, 5.0)
    assert far["in_basin"] is False and "r*=27" in far["verdict"] and "basin [0, 20]" in far["verdict"]
    assert far["E_ref_star"] == pytest.approx(4.4) and far["E_ref_star_minus_best"] == pytest.approx(1.0)


@pytest.mark.parametrize("kind, on_hard", [(None, True), ("mean-field", False)])
def test_reference_summary(kind, on_hard):
    s = reference_summary(FakeEvaluator(kind), ds.Problem(), 14.0, on_hard)  # estimator "auto"
    assert s == {"answer_on": "E_hard" if on_hard else "E_ref", "estimator": "auto",
                 "estimator_used": kind or "auto", "E_ref_star": pytest.approx(3.4), "E_ref_star_se": 0.14,
                 "draws": 32}
    assert type(s["draws"]) is int and type(s["E_ref_star"]) is float
