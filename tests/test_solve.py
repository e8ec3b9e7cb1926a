"""The solver on analytic objectives: sweep grids, the continuous solve and its guarantees."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

from diffsense.runtime._errors import InputError
from diffsense.solve import (
    BracketedSecant,
    SolveConfig,
    basin_check,
    default_steps,
    dense_grid_search,
    solve,
    sweep,
)
from tests._analytic_objectives import HI, LO, STEP_W, bowl, dip_at, ripple, staircase

BUDGET = 20
XTOL = SolveConfig().xtol_rel * (HI - LO)

# name -> (objective pair, where the argmin is, on a bound?)
CASES = {
    "bowl": (bowl(1.3), 1.3, False),
    "bowl_on_a_step": (bowl(np.deg2rad(90.0)), np.deg2rad(90.0), False),
    "staircase": (staircase(1.3), None, False),
    "lower_bound": (bowl(0.2), LO, True),
    "upper_bound": (bowl(4.0), HI, True),
    "staircase_upper_bound": (staircase(3.5), HI, True),
}


@pytest.fixture(scope="module")
def solved():
    """Each case solved once (each solve compiles its own objective)."""
    cache = {}

    def get(name, method="secant"):
        if (name, method) not in cache:
            (e2, eh), _, _ = CASES[name]
            cache[name, method] = solve(e2, eh, (LO, HI), config=SolveConfig(method=method))
        return cache[name, method]

    return get


def test_default_steps_paper_grid_and_round_spacing():
    np.testing.assert_allclose(default_steps(30.0, 180.0), [30, 60, 90, 120, 150, 180])
    np.testing.assert_allclose(default_steps(20.0, 160.0), np.arange(20.0, 161.0, 20.0))
    steps = default_steps(0.3, 1.0)
    assert 6 <= steps.size <= 8 and steps[0] == 0.3 and steps[-1] == 1.0
    with pytest.raises(InputError, match="LO must be smaller"):
        default_steps(180.0, 30.0)


def test_sweep_evaluates_hard_and_soft():
    e2, eh = bowl(1.0)
    points = sweep(eh, e2, [0.5, 1.0, 2.0])
    assert [p.r for p in points] == [0.5, 1.0, 2.0]
    for p in points:
        assert p.E_soft == pytest.approx(math.sqrt(1.0 + (p.r - 1.0) ** 2))
        assert p.E_hard == pytest.approx(p.E_soft)


@pytest.mark.parametrize("name", list(CASES))
def test_solve_finds_argmin_within_budget(solved, name):
    (_, eh), expected, on_bound = CASES[name]
    res = solved(name)
    best_step = min(p.E_hard for p in res.sweep)
    assert res.E_hard_star <= best_step
    assert res.evaluations["objective"] + res.evaluations["gradient"] <= BUDGET
    assert res.on_bound is on_bound
    assert float(eh(res.r_star)) == pytest.approx(res.E_hard_star)
    if expected is not None:
        assert abs(res.r_star - expected) <= XTOL
    assert all(math.isfinite(v) for v in (res.r_star, res.E_soft_star, res.E_hard_star))


def test_staircase_answer_sits_on_the_best_plateau(solved):
    # The hard staircase is best (q = 1.3 exactly) on the plateau [1.25, 1.30).
    res = solved("staircase")
    assert 1.25 - 1e-9 <= res.r_star < 1.30
    assert res.E_hard_star == pytest.approx(1.0)
    # Best step: 60 deg (q = 1.05), so the bracket is its neighbours 30 and 90 deg.
    assert res.bracket == pytest.approx((np.deg2rad(30.0), np.deg2rad(90.0)))


@pytest.mark.parametrize("center", [1.3, 4.0])
def test_evaluation_counts_are_exact(center):
    # Count real executions of the soft objective (a callback runs once per forward pass,
    # inside the compiled root find too) and calls of the hard one.
    calls = {"soft": 0, "hard": 0}
    e2, eh = ripple(center)

    def bump(_):
        calls["soft"] += 1

    def e2_counted(r, tau):
        jax.debug.callback(bump, r)
        return e2(r, tau)

    def eh_counted(r):
        calls["hard"] += 1
        return eh(r)

    res = solve(e2_counted, eh_counted, (LO, HI))
    n = len(res.sweep)
    assert calls["hard"] - n + calls["soft"] - n == sum(res.evaluations.values())
    assert calls["soft"] - n >= res.evaluations["gradient"]


def test_continuation_levels_track_the_minimum(solved):
    res = solved("bowl")
    assert [lv.tau for lv in res.levels] == [4.0, 2.0, 1.0]
    assert all(lv.converged and lv.bound == 0 for lv in res.levels)
    assert res.notes == ()


def test_continuation_finds_the_basin_a_single_temperature_misses():
    # Ripples make local minima at tau = 1; from the best step a tau = 1 solve stops in the
    # nearest one, the continuation (4, 2, 1) follows the smoothed bowl into the best basin.
    e2, eh = ripple(1.3)
    dense = dense_grid_search(eh, (LO, HI), float(np.deg2rad(0.5)))
    res = solve(e2, eh, (LO, HI))
    assert basin_check(dense, res.r_star, res.E_hard_star, res.bracket) is None
    assert res.E_hard_star <= dense.E_hard.min() + 1e-4
    assert res.evaluations["objective"] + res.evaluations["gradient"] <= BUDGET
    # Without the continuation (and without the hard polish, which could hop basins on its own).
    single = solve(e2, eh, (LO, HI), config=SolveConfig(tau_schedule=(1.0,), hard_polish=0))
    assert "outside the basin" in basin_check(dense, single.r_star, single.E_hard_star)


def test_bisection_method_keeps_the_guarantees(solved):
    # optx.Bisection needs more evaluations than the secant: with the same budget it may stop
    # early, but the answer is still chosen on the hard objective.
    for name in ("bowl", "lower_bound"):
        res = solved(name, "bisection")
        assert res.E_hard_star <= min(p.E_hard for p in res.sweep)
        assert res.evaluations["objective"] + res.evaluations["gradient"] <= BUDGET


def test_hard_objective_overrules_a_worse_soft_optimum():
    # Soft minimum at 1.3, but the hard objective is only good at the 90-deg step.
    r_dip = float(np.deg2rad(90.0))
    e2, eh = dip_at(r_dip, center=1.3)
    res = solve(e2, eh, (LO, HI))
    # The best step wins, then the hard polish walks inside the dip towards the bowl's centre.
    assert abs(res.r_star - r_dip) <= 0.01 and res.r_star <= r_dip
    assert res.E_hard_star <= float(eh(r_dip)) <= min(p.E_hard for p in res.sweep)
    assert any("worse than the best step" in n for n in res.notes)
    unpolished = solve(e2, eh, (LO, HI), config=SolveConfig(hard_polish=0))
    assert unpolished.r_star == pytest.approx(r_dip)
    assert res.evaluations["objective"] + res.evaluations["gradient"] <= BUDGET


def test_hard_polish_finds_a_better_hard_point_next_to_the_soft_optimum():
    # The soft bowl has its minimum at 1.3; the hard objective is 0.05 m better only within
    # 0.01 rad of 1.33, finer than the soft objective can show.
    e2, eh = dip_at(1.33, center=1.3, penalty=0.05)
    plain = solve(e2, eh, (LO, HI), config=SolveConfig(hard_polish=0))
    assert abs(plain.r_star - 1.3) <= XTOL and plain.E_hard_star == pytest.approx(1.05, abs=1e-6)
    res = solve(e2, eh, (LO, HI))
    assert abs(res.r_star - 1.33) <= 0.01
    assert res.E_hard_star < plain.E_hard_star - 0.04
    assert float(eh(res.r_star)) == pytest.approx(res.E_hard_star)
    assert any(n.startswith("hard polish") for n in res.notes)
    used = res.evaluations["objective"] + res.evaluations["gradient"]
    assert used <= BUDGET
    # The polish spends at most its own allowance on top of the unpolished solve (+1: E_soft
    # at the moved r*).
    plain_used = plain.evaluations["objective"] + plain.evaluations["gradient"]
    assert used <= plain_used + SolveConfig().hard_polish + 1


def test_reserved_polish_is_not_starved_by_a_hungry_continuation():
    # A rippled bowl whose hard objective is 0.05 m better only within 0.01 rad of 1.385, just
    # beside the soft optimum (~1.37). A tight tolerance makes the continuation spend the budget.
    e2, eh_rippled = ripple(1.3)

    def eh(r):
        return eh_rippled(r) + 0.05 * (jnp.abs(jnp.asarray(r) - 1.385) > 0.01)

    cfg = SolveConfig(xtol_rel=1e-6)
    hungry = solve(e2, eh, (LO, HI), config=cfg)
    assert not any(n.startswith("hard polish") for n in hungry.notes)  # nothing left for it
    reserved = solve(e2, eh, (LO, HI), config=SolveConfig(xtol_rel=1e-6, reserve_polish=True))
    assert any(n.startswith("hard polish") for n in reserved.notes)
    assert abs(reserved.r_star - 1.385) <= 0.01
    assert reserved.E_hard_star < hungry.E_hard_star - 0.04
    soft_levels = sum(level.gradient_evaluations for level in reserved.levels)
    assert soft_levels <= BUDGET - 2 - cfg.hard_polish
    assert reserved.evaluations["objective"] + reserved.evaluations["gradient"] <= BUDGET


def test_float32_outer_problem_and_small_temperatures():
    e2, eh = staircase(1.3)
    cfg = SolveConfig(dtype="float32", tau_schedule=(1.0, 0.1, 0.01))
    res = solve(e2, eh, (LO, HI), config=cfg)
    assert res.E_hard_star <= min(p.E_hard for p in res.sweep)
    assert all(math.isfinite(v) for v in (res.r_star, res.E_soft_star, res.E_hard_star))


def test_given_sweep_is_reused_and_custom_steps_are_checked():
    e2, eh = bowl(1.3)
    points = sweep(eh, e2, default_steps(LO, HI))
    res = solve(e2, eh, (LO, HI), sweep_points=points)
    assert res.sweep == points
    with pytest.raises(InputError, match="leave the interval"):
        solve(e2, eh, (LO, HI), steps=[0.1, 1.0])


def test_nan_gradient_is_reported():
    def e2(r, tau):
        return jnp.sqrt(r - 10.0) + tau  # NaN everywhere on the interval

    with pytest.raises(FloatingPointError, match="not finite"):
        solve(e2, lambda r: 1.0, (LO, HI))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(tau_schedule=(1.0, 2.0)), "must not increase"),
        (dict(tau_schedule=(0.0,)), "positive"),
        (dict(xtol_rel=0.0), "xtol_rel"),
        (dict(max_evaluations=5), "too small"),
        (dict(hard_polish=-1), "hard_polish"),
        (dict(max_evaluations=14, reserve_polish=True), "reserved hard polish"),
    ],
)
def test_bad_config_is_one_clear_error(kwargs, match):
    with pytest.raises(InputError, match=match):
        SolveConfig(**kwargs)


def test_bracketed_secant_under_jit_minimum_not_maximum():
    # g has a root at 0 (a maximum of E: g goes + to -) and at +-1 (minima): start near the max.
    def g(r, _):
        return r**3 - r

    @jax.jit
    def find(r0):
        sol = optx.root_find(
            g, BracketedSecant(rtol=0.0, atol=1e-9), r0, options=dict(lower=-0.5, upper=2.0),
            throw=False,
        )
        return sol.value, sol.stats["num_steps"], sol.state.bound

    r, steps, bound = find(jnp.asarray(0.01))
    assert float(r) == pytest.approx(1.0, abs=1e-8)
    assert int(bound) == 0 and int(steps) <= 20


def test_dense_grid_and_basin_check(solved):
    _, eh = CASES["staircase"][0]
    dense = dense_grid_search(eh, (LO, HI), float(np.deg2rad(0.5)))
    assert dense.evaluations == dense.r.size == 301
    assert dense.r[0] == LO and dense.r[-1] == HI
    a, b = dense.basin()
    assert a <= dense.r[dense.best_index] <= b
    res = solved("staircase")
    assert basin_check(dense, res.r_star, res.E_hard_star, res.bracket) is None
    assert res.E_hard_star <= dense.E_hard.min() + 1e-12
    with pytest.raises(InputError):
        dense_grid_search(eh, (LO, HI), 0.0)


def test_basin_check_explains_a_miss():
    # Two basins: the global one at r = 1 and a shallower one at r = 2.5 (or equally deep).
    def two_basins(penalty):
        return lambda r: 1.0 + 0.3 * (r - 1.0) ** 2 * (r - 2.5) ** 2 + penalty * (r > 2.0)

    dense = dense_grid_search(two_basins(0.05), (LO, HI), 0.01)
    a, b = dense.basin()
    assert a < 1.0 < b < 2.5
    assert basin_check(dense, 1.0) is None
    reason = basin_check(dense, 2.5, 1.05, bracket=(2.0, 3.0))
    assert "outside the basin" in reason and "worse by" in reason and "does not bracket" in reason
    reason = basin_check(dense, 2.5, 1.05, bracket=(0.6, 3.0))
    assert "soft objective's minimum misses the hard basin" in reason
    equal = dense_grid_search(two_basins(0.0), (LO, HI), 0.01)
    other_minimum = 2.5 if equal.r[equal.best_index] < 1.75 else 1.0
    assert "at least as deep" in basin_check(equal, other_minimum, 1.0)


def test_basin_includes_plateaus():
    _, eh = staircase(1.3)
    dense = dense_grid_search(eh, (1.0, 1.6), STEP_W / 5)
    a, b = dense.basin()
    # The best plateau [1.25, 1.30) and the rising steps on both sides belong to the basin.
    assert a == pytest.approx(1.0) and b == pytest.approx(1.6)


def test_hard_grid_solve_searches_the_best_bracket_with_the_budget():
    from diffsense.solve import hard_grid_solve

    calls = []
    _, eh = bowl(1.3)

    def counted(r):
        calls.append(float(r))
        return eh(r)

    res = hard_grid_solve(counted, (LO, HI), max_evaluations=10)
    steps = [p.r for p in res.sweep]
    assert len(calls) == len(steps) * 2 + 10  # sweep (hard, and E_soft = E_hard^2) + inner grid
    assert res.evaluations == {"objective": 10, "gradient": 0}
    # The inner grid is 10 even points strictly inside the bracket of the best step (60 or 90 deg).
    assert all(res.bracket[0] < r < res.bracket[1] for r in calls[-10:])
    assert res.E_hard_star <= min(p.E_hard for p in res.sweep)
    assert abs(res.r_star - 1.3) <= (res.bracket[1] - res.bracket[0]) / 11
    assert float(eh(res.r_star)) == pytest.approx(res.E_hard_star)
