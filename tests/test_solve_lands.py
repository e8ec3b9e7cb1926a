"""The continuous solve lands on the argmin of analytic objectives whose minimum is known by hand,
with either method, every continuation level included, and keeps its guarantees: never worse on
E_hard than the best step, within the evaluation budget, E_hard_star = E_hard(r_star).

Interval: HFOV 30..180 deg in radians, steps every 30 deg; XTOL = 1e-3 of the interval
(0.00262 rad = 0.15 deg), the default tolerance.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.runtime import InputError
from diffsense.solve import SolveConfig, dense_grid_search, solve
from tests._analytic_objectives import HI, LO, bowl, ripple, staircase

BUDGET = SolveConfig().max_evaluations
XTOL = SolveConfig().xtol_rel * (HI - LO)
METHODS = ("secant", "bisection")
DEG = np.pi / 180.0


def _used(res):
    return res.evaluations["objective"] + res.evaluations["gradient"]


def _guarantees(res, e_hard, budget=BUDGET):
    assert res.E_hard_star <= min(p.E_hard for p in res.sweep)
    assert float(e_hard(res.r_star)) == pytest.approx(res.E_hard_star)
    assert _used(res) <= budget
    assert sum(lv.gradient_evaluations for lv in res.levels) == res.evaluations["gradient"]
    assert all(math.isfinite(v) for v in (res.r_star, res.E_soft_star, res.E_hard_star))


# A bowl's soft minimum is its centre at every temperature: each level lands there too, within
# its own tolerance (xtol * tau / tau_last), not only the final answer.
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("center", [0.6, 1.0, 1.3, 2.2, 3.1])
def test_interior_minimum_of_a_bowl(method, center):
    e2, eh = bowl(center)
    res = solve(e2, eh, (LO, HI), config=SolveConfig(method=method))
    _guarantees(res, eh)
    assert abs(res.r_star - center) <= XTOL and not res.on_bound
    assert res.E_hard_star == pytest.approx(1.0, abs=1e-5)  # sqrt(1 + xtol^2) - 1 < 4e-6
    assert [lv.tau for lv in res.levels] == [4.0, 2.0, 1.0]
    for level in res.levels:
        assert abs(level.r - center) <= XTOL * level.tau, level
        assert level.bound == 0 and level.converged


@pytest.mark.parametrize("method", METHODS)
def test_a_single_level_lands_from_the_best_step(method):
    # Without the continuation the one level finds 1.3 on its own from the 60-deg step
    # (bisection: bracketing walk then halving; a flipped sign would end on a bracket edge).
    e2, eh = bowl(1.3)
    res = solve(e2, eh, (LO, HI), config=SolveConfig(method=method, tau_schedule=(1.0,), hard_polish=0))
    assert abs(res.levels[0].r - 1.3) <= XTOL and abs(res.r_star - 1.3) <= XTOL
    assert res.bracket == pytest.approx((30 * DEG, 90 * DEG))


def test_a_minimum_on_a_step_is_found_with_one_gradient_a_level():
    # Centre exactly on the 90-deg step: dE^2/dr = 0 at the warm start of every level.
    center = float(np.deg2rad(90.0))
    e2, eh = bowl(center)
    res = solve(e2, eh, (LO, HI), config=SolveConfig(method="bisection"))
    assert [(lv.r, lv.gradient_evaluations, lv.bound) for lv in res.levels] == [(center, 1, 0)] * 3
    assert res.r_star == center


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("center, end, bound", [(0.2, LO, -1), (4.0, HI, 1)])
def test_minimum_beyond_the_interval_lands_on_its_bound(method, center, end, bound):
    e2, eh = bowl(center)
    res = solve(e2, eh, (LO, HI), config=SolveConfig(method=method))
    _guarantees(res, eh)
    assert res.r_star == end and res.on_bound
    assert res.E_hard_star == pytest.approx(np.sqrt(1.0 + (end - center) ** 2))
    assert all(level.bound == bound for level in res.levels)


@pytest.mark.parametrize("method", METHODS)
def test_a_hump_sends_the_answer_to_the_lower_end_of_e(method):
    # E^2 = 10 - (r - 1.2)^2 is largest at 1.2: the best point of [30, 180] deg is the end
    # farther from 1.2, i.e. 180 deg (E^2 = 10 - 1.9416^2 = 6.23 vs 10 - 0.676^2 = 9.54).
    def e2(r, tau):
        del tau
        return 10.0 - (r - 1.2) ** 2

    res = solve(e2, lambda r: jnp.sqrt(e2(r, 1.0)), (LO, HI), config=SolveConfig(method=method))
    assert res.r_star == HI and res.on_bound
    assert res.E_hard_star == pytest.approx(np.sqrt(10.0 - (HI - 1.2) ** 2))


@pytest.mark.parametrize("method", METHODS)
def test_staircase_lands_on_its_best_plateau(method):
    # q(r) = 0.05 * #{edges <= r} equals 1.3 exactly on [1.25, 1.30): E_hard = 1 there only.
    # The best step is 60 deg (q = 1.05): the bracket is its neighbours 30 and 90 deg.
    e2, eh = staircase(1.3)
    res = solve(e2, eh, (LO, HI), config=SolveConfig(method=method))
    _guarantees(res, eh)
    assert 1.25 - 1e-9 <= res.r_star < 1.30 and res.E_hard_star == pytest.approx(1.0)
    assert res.bracket == pytest.approx((30 * DEG, 90 * DEG))
    # q(pi) = 0.05 x 63 = 3.15 < 3.5: a staircase rising to the interval's end is best there
    e2, eh = staircase(3.5)
    res = solve(e2, eh, (LO, HI), config=SolveConfig(method=method))
    _guarantees(res, eh)
    assert res.r_star == HI and res.on_bound


# Bisection walks and halves where the secant extrapolates: on the ripple (its soft optimum
# moves 0.06 rad between levels) it needs about 30 evaluations to settle each level, against
# 12 for the secant; at the default 20 it stops early, still inside the best basin.
@pytest.mark.parametrize("method, budget", [("secant", 20), ("bisection", 20), ("bisection", 30)])
def test_ripple_continuation_lands_in_the_best_basin(method, budget):
    e2, eh = ripple(1.3)
    dense = dense_grid_search(eh, (LO, HI), 0.5 * DEG)  # the 0.5-deg reference grid
    a, b = dense.basin()
    res = solve(e2, eh, (LO, HI), config=SolveConfig(method=method, max_evaluations=budget))
    _guarantees(res, eh, budget)
    assert a <= res.r_star <= b
    if method == "secant" or budget == 30:
        assert res.E_hard_star <= dense.E_hard.min() + 1e-4
        assert all(level.converged for level in res.levels)


def test_bisection_on_a_steep_bowl_keeps_to_its_budget():
    # E^2 = 1 + 1e4 (r - 1.3)^2: the halving count (not |dE^2/dr|) decides when bisection stops:
    # 11 gradients for the first level (walk 5 + halve 5 + 1), then 2 and 3, as on a shallow bowl.
    def e2(r, tau):
        del tau
        return 1.0 + 1e4 * (r - 1.3) ** 2

    res = solve(e2, lambda r: jnp.sqrt(e2(r, 1.0)), (LO, HI), config=SolveConfig(method="bisection"))
    assert abs(res.r_star - 1.3) <= XTOL and _used(res) <= BUDGET and res.notes == ()
    assert [lv.gradient_evaluations for lv in res.levels] == [11, 2, 3]
    assert all(abs(lv.r - 1.3) <= XTOL * lv.tau and lv.converged for lv in res.levels)


def test_soft_e_below_one_metre_is_its_square_root():
    # E^2 = 0.25 + (r - 1.3)^2: E_soft at the answer is 0.5 m (the root is floored at 0, not 1).
    def e2(r, tau):
        del tau
        return 0.25 + (r - 1.3) ** 2

    res = solve(e2, lambda r: math.sqrt(0.25 + (float(r) - 1.3) ** 2), (LO, HI))
    assert res.E_soft_star == pytest.approx(0.5, abs=1e-5)


@pytest.mark.parametrize("method", METHODS)
def test_a_float32_solve_stays_in_float32(method):
    # Every r and tau the objectives are given is float32 (in the sweep too), every level lands
    # on a float32 number, and the answer is the bowl's centre to the tolerance.
    e2, e_hard = bowl(1.3)
    dtypes = set()

    def e2_seen(r, tau):
        dtypes.update((jnp.asarray(r).dtype, jnp.asarray(tau).dtype))
        return e2(r, tau)

    def e_hard_seen(r):
        dtypes.add(jnp.asarray(r).dtype)
        return e_hard(r)

    res = solve(e2_seen, e_hard_seen, (LO, HI), config=SolveConfig(dtype="float32", method=method))
    assert dtypes == {jnp.dtype("float32")}
    assert all(float(np.float32(level.r)) == level.r for level in res.levels)
    assert abs(res.r_star - 1.3) <= XTOL


def test_a_float32_staircase_at_small_temperatures_stays_finite():
    e2, eh = staircase(1.3)
    res = solve(e2, eh, (LO, HI), config=SolveConfig(dtype="float32", tau_schedule=(1.0, 0.1, 0.01)))
    _guarantees(res, eh)


def test_float64_outer_solve_needs_x64_and_float32_does_not():
    e2, e_hard = bowl(1.3)
    with jax.enable_x64(False):
        with pytest.raises(InputError, match="x64"):
            solve(e2, e_hard, (LO, HI))
        res = solve(e2, e_hard, (LO, HI), config=SolveConfig(dtype="float32"))
    assert abs(res.r_star - 1.3) <= XTOL
