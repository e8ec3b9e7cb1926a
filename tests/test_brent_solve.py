"""`solve` with `SolveConfig(method="brent")`: the stepped sweep, then Brent's bounded
minimisation of the answer objective's values inside the best step's bracket. It lands on
minima known by hand, never reads the soft objective, keeps to its budget, and is never worse
than the best step; "auto" is the secant continuation where `solve` is called directly.

Interval: HFOV 30..180 deg in radians, steps every 30 deg (tests/_analytic_objectives.py).
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.solve import SolveConfig, solve
from tests._analytic_objectives import HI, LO, bowl, staircase

BRENT = SolveConfig(method="brent")
XTOL = BRENT.xtol_rel * (HI - LO)


def _no_soft(r, tau):
    raise AssertionError("Brent reads the answer objective only")


def _counted(e_hard):
    calls = []

    def f(r):
        calls.append(float(r))
        return e_hard(r)

    return f, calls


@pytest.mark.parametrize("center", [0.6, 1.0, 1.3, 2.2, 3.1])
def test_a_bowls_centre_within_the_tolerance_from_values_alone(center):
    _, e_hard = bowl(center)
    f, calls = _counted(e_hard)
    res = solve(_no_soft, f, (LO, HI), config=BRENT)
    assert abs(res.r_star - center) <= XTOL and not res.on_bound
    assert res.evaluations == {"objective": len(calls) - 6, "gradient": 0}  # six sweep steps
    assert res.evaluations["objective"] <= BRENT.max_evaluations
    assert res.E_hard_star == pytest.approx(float(e_hard(res.r_star)), rel=1e-12)
    assert res.levels == () and res.tau_schedule == ()


def test_a_parabola_is_found_by_its_first_parabolic_step():
    # Brent fits a parabola through three points; on an exact parabola its vertex is the answer,
    # so it needs far fewer values than a golden section (~log(0.5 / XTOL) / log(1.618) = 11).
    _, e_hard = bowl(1.3)
    res = solve(_no_soft, lambda r: float(e_hard(r)) ** 2, (LO, HI), config=BRENT)
    assert abs(res.r_star - 1.3) <= XTOL and res.evaluations["objective"] <= 6


def test_the_answer_is_never_worse_than_the_best_step_and_presses_on_a_bound():
    for center, end in [(0.2, LO), (4.0, HI)]:
        _, e_hard = bowl(center)
        res = solve(_no_soft, e_hard, (LO, HI), config=BRENT)
        assert res.r_star == end and res.on_bound
        assert res.E_hard_star == pytest.approx(math.sqrt(1.0 + (end - center) ** 2))


def test_a_staircase_ends_on_its_best_plateau():
    # q = 1.3 exactly on [1.25, 1.30): E_hard = 1 there only; steps of 0.05 are far above XTOL
    _, e_hard = staircase(1.3)
    res = solve(_no_soft, e_hard, (LO, HI), config=BRENT)
    assert 1.25 - 1e-9 <= res.r_star < 1.30 and res.E_hard_star == pytest.approx(1.0)


def test_the_budget_is_kept_and_said():
    _, e_hard = bowl(1.3)
    res = solve(_no_soft, e_hard, (LO, HI), config=SolveConfig(method="brent", max_evaluations=3))
    assert res.evaluations["objective"] == 3
    assert any("budget" in note for note in res.notes)


def test_in_float32_every_r_is_a_float32_number():
    _, e_hard = bowl(1.3)
    seen = []

    def f(r):
        seen.append(np.asarray(r).dtype)
        return e_hard(r)

    res = solve(_no_soft, f, (LO, HI), config=SolveConfig(method="brent", dtype="float32"))
    assert set(seen) == {np.dtype("float32")}
    assert abs(res.r_star - 1.3) <= 2 * XTOL


def test_auto_is_the_secant_continuation_when_solve_is_called_directly():
    e2, e_hard = bowl(1.3)
    auto = solve(e2, e_hard, (LO, HI))
    secant = solve(e2, e_hard, (LO, HI), config=SolveConfig(method="secant"))
    same = ("r_star", "E_hard_star", "evaluations", "levels", "notes")
    assert [getattr(auto, k) for k in same] == [getattr(secant, k) for k in same]
    assert auto.evaluations["gradient"] > 0


def test_the_sweep_it_is_given_is_not_evaluated_again():
    _, e_hard = bowl(2.2)
    first = solve(_no_soft, e_hard, (LO, HI), config=BRENT)
    f, calls = _counted(e_hard)
    again = solve(_no_soft, f, (LO, HI), config=BRENT, sweep_points=first.sweep)
    assert len(calls) == again.evaluations["objective"] and again.r_star == first.r_star
    assert jnp.isfinite(again.E_hard_star)
