"""The continuous solve's edge behaviour, pinned by hand (each test kills a surviving mutant of
docs/mutation.md's solve run)."""

from __future__ import annotations

import dataclasses
import time

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.runtime._errors import InputError
from diffsense.solve import SolveConfig, solve
from tests._analytic_objectives import HI, LO, bowl, dip_at, ripple

# Interval (0, 1), steps 0, 0.5, 1, one level with tol = 1/128 (exact in binary).
WALK = SolveConfig(method="bisection", tau_schedule=(1.0,), xtol_rel=1 / 128, hard_polish=0,
                   max_evaluations=12)


def _bowl_with_nan_gradient(center: float, nan_at):
    """E^2 = 1 + (r - center)^2 whose dE^2/dr is NaN where `nan_at(r)` is true."""

    @jax.custom_jvp
    def e2(r, tau):
        del tau
        return 1.0 + (r - center) ** 2

    @e2.defjvp
    def _jvp(primals, tangents):
        r, _ = primals
        slope = jnp.where(nan_at(r), jnp.nan, 2.0 * (r - center))
        return e2(*primals), slope * tangents[0]

    return e2


def test_bisection_reports_a_gradient_not_finite_throughout_its_bracket():
    # Minimum at 0.004: the walk down from 0.5 probes 0.5 - tol (2^k - 1), all g > 0, down to
    # 0.0078125 and then 0.0 (clipped, g < 0): the bracket [0, 0.0078125]. Every point the
    # halving asks for lies inside it, where g is NaN: an error, not an answer.
    e2 = _bowl_with_nan_gradient(0.004, lambda r: (r > 0.0) & (r < 0.0078125))
    _, e_hard = bowl(0.5)  # the hard objective makes 0.5 the best step
    with pytest.raises(FloatingPointError, match=r"not finite in \[0.0, 0.0078125\]"):
        solve(e2, e_hard, (0.0, 1.0), steps=[0.0, 0.5, 1.0], config=WALK)


def _secant_on_the_bowl(config: SolveConfig):
    """The secant on E^2 = 1 + (r - 1.3)^2 through a host value_and_grad: (result, the points
    each temperature's gradient was asked at, in order)."""
    calls = []

    def value_and_grad(r, tau):
        calls.append((r, tau))
        return 1.0 + (r - 1.3) ** 2, 2.0 * (r - 1.3)

    traced = []  # with a host value_and_grad, the secant and the sweep never trace e2_soft
    res = solve(lambda r, tau: traced.append(r) or 1.0, bowl(1.3)[1], (LO, HI), config=config,
                value_and_grad=value_and_grad)
    assert traced == [] and [p.E_soft for p in res.sweep] == pytest.approx(
        [np.sqrt(1.0 + (r - 1.3) ** 2) for r in np.deg2rad([30, 60, 90, 120, 150, 180])])
    after_sweep = calls[len(res.sweep):]
    return res, {tau: [r for r, t in after_sweep if t == tau] for tau in config.tau_schedule}


def test_later_levels_probe_near_the_previous_answer():
    # From the 60-deg step, bracket (30, 90) deg = pi/3 rad wide. The first level probes a
    # quarter bracket (pi/12) away; the second level, warm-started at the first's answer r0
    # (g > 0 there: it probes downhill), 1/16 of the bracket (pi/48) away; the third by the
    # larger of the second level's move and twice the second level's tolerance.
    res, points = _secant_on_the_bowl(SolveConfig())
    r0, r1 = res.levels[0].r, res.levels[1].r
    assert points[4.0][:2] == pytest.approx([np.pi / 3, np.pi / 3 + np.pi / 12], abs=1e-12)
    assert points[2.0][:2] == pytest.approx([r0, r0 - np.pi / 48], abs=1e-12)
    # 2 tol of the second level (tau = 2: tol = 2 xtol) beats its move |r1 - r0| (< xtol)
    xtol = SolveConfig().xtol_rel * (HI - LO)
    assert abs(r1 - r0) < xtol and points[1.0][:2] == pytest.approx([r1, r1 - 4 * xtol], abs=1e-12)


def test_second_level_probes_twice_the_first_tolerance_when_that_is_wider():
    # xtol_rel = 0.006: the first level's tol (tau = 4) is 4 x 0.006 x 150 deg = 0.0628 rad,
    # twice that (0.126) beats 1/16 of the bracket (0.065): the second level's first probe.
    res, points = _secant_on_the_bowl(SolveConfig(xtol_rel=0.006))
    r0 = res.levels[0].r
    assert points[2.0][0] == r0
    assert abs(points[2.0][1] - r0) == pytest.approx(8 * 0.006 * (HI - LO), abs=1e-12)


# The compass search probe by probe, on an interval (0, 1) whose steps leave one end unevaluated:
# the soft bowl's minimum 0.5 is worse on E_hard than the best step, so the polish starts there.
# Bracket (0, 1): first step 1/16; xtol_rel = 1/64 makes 1/64 the finest step it may take.
@pytest.mark.parametrize("steps, hard_center, polish, probes", [
    # from 0.0625: 0.125 (worse), 0.0 (better, the bound: moves); from 0: 0.0625 (worse), -0.0625
    # (outside: free); 1/32: 0.03125 (worse), 1/64: 0.015625 (worse); 1/128 is finer than 1/64.
    ([0.0625, 1.0], 0.0, 6, [0.125, 0.0, 0.0625, 0.03125, 0.015625]),
    # from 0.9375: 1.0 (better, the bound: moves); from 1: 1.0625 (outside: free, the other side
    # is still probed) 0.9375 (worse); 1/32: 0.96875 (worse); 1/64: 0.984375 (worse).
    ([0.0, 0.9375], 1.0, 6, [1.0, 0.9375, 0.96875, 0.984375]),
    ([0.0, 0.9375], 1.0, 1, [1.0]),  # a polish of one probe
])
def test_hard_polish_probe_sequence_reaches_an_unevaluated_bound(steps, hard_center, polish,
                                                                probes):
    hard_calls = []

    def e_hard(r):
        hard_calls.append(float(r))
        return float(np.sqrt(1.0 + (float(r) - hard_center) ** 2))

    def value_and_grad(r, tau):  # E^2 = tau + (r - 0.5)^2: the bowl at tau = 1
        return tau + (r - 0.5) ** 2, 2.0 * (r - 0.5)

    cfg = SolveConfig(tau_schedule=(1.0,), xtol_rel=1 / 64, hard_polish=polish)
    res = solve(bowl(0.5)[0], e_hard, (0.0, 1.0), steps=steps, config=cfg,
                value_and_grad=value_and_grad)
    assert res.bracket == (0.0, 1.0)
    # after the sweep's two steps and E_hard at the soft optimum (~0.5, within tol):
    assert abs(hard_calls[2] - 0.5) <= 1 / 64 and hard_calls[3:] == probes
    assert res.r_star == hard_center and res.E_hard_star == 1.0 and res.on_bound
    assert res.E_soft_star == pytest.approx(np.sqrt(1.25), abs=1e-15)  # at the polished r*


def test_float64_outer_solve_needs_x64_and_float32_does_not():
    e2, e_hard = bowl(1.3)
    with jax.enable_x64(False):
        with pytest.raises(InputError, match="needs jax_enable_x64"):
            solve(e2, e_hard, (LO, HI))
        res = solve(e2, e_hard, (LO, HI), config=SolveConfig(dtype="float32"))
    assert abs(res.r_star - 1.3) <= SolveConfig().xtol_rel * (HI - LO)


@pytest.mark.parametrize("method", ["secant", "bisection"])
def test_float32_solve_stays_in_float32(method):
    # Every point either method's levels land on is a float32 number (float64 arithmetic would
    # leave the float32 grid), and the answer is the bowl's centre to the tolerance.
    e2, e_hard = bowl(1.3)
    dtypes = set()  # of every r and tau the objectives are given, in the sweep too

    def e2_seen(r, tau):
        dtypes.update((jnp.asarray(r).dtype, jnp.asarray(tau).dtype))
        return e2(r, tau)

    def e_hard_seen(r):
        dtypes.add(jnp.asarray(r).dtype)
        return e_hard(r)

    res = solve(e2_seen, e_hard_seen, (LO, HI), config=SolveConfig(dtype="float32", method=method))
    assert dtypes == {jnp.dtype("float32")}
    for level in res.levels:
        assert float(np.float32(level.r)) == level.r, level
    assert abs(res.r_star - 1.3) <= SolveConfig().xtol_rel * (HI - LO)


def test_sweep_soft_column_is_at_the_last_temperature():
    # E^2 = tau + (r - 1.3)^2 under the schedule (2, 0.5): the sweep reports E_soft at tau = 0.5.
    def value_and_grad(r, tau):
        return tau + (r - 1.3) ** 2, 2.0 * (r - 1.3)

    steps = np.deg2rad([30.0, 60.0, 90.0, 120.0, 150.0, 180.0])
    res = solve(bowl(1.3)[0], bowl(1.3)[1], (LO, HI), steps=steps,
                config=SolveConfig(tau_schedule=(2.0, 0.5)), value_and_grad=value_and_grad)
    assert [p.E_soft for p in res.sweep] == pytest.approx(np.sqrt(0.5 + (steps - 1.3) ** 2))


@pytest.mark.parametrize("tau_schedule", [(1.0,), (0.5,)])
def test_a_level_tolerance_is_capped_at_an_eighth_of_the_bracket(tau_schedule):
    # Interval (1, 3), best step 2, bracket (1, 3); xtol = 0.25 x 2 = 0.5 at the last level,
    # whatever its temperature, capped to (3 - 1) / 8 = 0.25. Bisection from 2 towards the
    # minimum 2.2: probe 2.25 (+) closes [2, 2.25], one tol wide: one halving at 2.125 (-),
    # answer 2.1875.
    e2, _ = bowl(2.2)
    cfg = SolveConfig(method="bisection", tau_schedule=tau_schedule, xtol_rel=0.25, hard_polish=0)
    res = solve(e2, bowl(2.0)[1], (1.0, 3.0), steps=[1.0, 2.0, 3.0], config=cfg)
    level = res.levels[0]
    assert res.bracket == (1.0, 3.0) and level.converged
    assert level.r == 2.1875 and level.gradient_evaluations == 3


@pytest.mark.parametrize("method", ["secant", "bisection"])
def test_soft_minimum_pressing_on_a_bracket_edge_is_noted(method):
    # E_hard's bowl at 0.6 makes 30 deg the best step (bracket (30, 60) deg); the soft bowl's
    # minimum 1.3 lies beyond 60 deg = 1.0472 rad, an edge of the bracket but not of the interval.
    res = solve(bowl(1.3)[0], bowl(0.6)[1], (LO, HI), config=SolveConfig(method=method))
    assert res.levels[-1].r == pytest.approx(np.pi / 3) and res.levels[-1].bound == 1
    assert any(n.startswith("the soft minimum at tau=1 presses on the bracket edge r=1.0472")
               for n in res.notes), res.notes


def test_an_earlier_level_answer_wins_when_the_last_is_worse_than_the_best_step():
    # The rippled bowl's three levels (tau 4, 2, 1) answer r0, r1, r2; E_hard is made 1 m worse
    # within 0.003 rad of r0 and r2 only (no sweep step is that close, so the bracket and the
    # levels stay the same): of r2, r0, r1 and the best step, r1 is best on E_hard.
    e2, e_hard = ripple(1.3)
    plain = solve(e2, e_hard, (LO, HI), config=SolveConfig(hard_polish=0))
    r0, r1, r2 = (level.r for level in plain.levels)

    def e_hard_penalised(r):
        r = jnp.asarray(r)
        return e_hard(r) + 1.0 * ((jnp.abs(r - r2) < 0.003) | (jnp.abs(r - r0) < 0.003))

    res = solve(e2, e_hard_penalised, (LO, HI), config=SolveConfig(hard_polish=0))
    assert [level.r for level in res.levels] == [r0, r1, r2]
    assert res.r_star == r1 and res.E_hard_star == pytest.approx(float(e_hard(r1)))
    note = f"has E_hard={float(e_hard_penalised(r2)):.6g} m, worse than the best step"
    assert any("is the best of 4 candidates" in n and note in n for n in res.notes), res.notes


@pytest.mark.parametrize("budget", [11, 13])
def test_earlier_levels_are_not_candidates_beyond_the_budget(budget):
    # E_hard is good only within 0.01 rad of the 90-deg step. After the levels' gradients and
    # E_hard at the soft optimum, earlier levels are evaluated while more than one evaluation
    # is left (the last is kept for E_soft): none at 11 (9 + 1 spent), the first at 13 (10 + 1).
    r_step = float(np.deg2rad(90.0))
    e2, e_hard = dip_at(r_step, center=1.3)
    hard_calls = []
    res = solve(e2, lambda r: hard_calls.append(float(r)) or e_hard(r), (LO, HI),
                config=SolveConfig(max_evaluations=budget, hard_polish=0))
    spent = res.evaluations["gradient"] + 1
    earlier = min(2, budget - 1 - spent)
    assert earlier == {11: 0, 13: 1}[budget]
    assert hard_calls[len(res.sweep):] == [lv.r for lv in res.levels[-1:] + res.levels[:earlier]]
    assert res.evaluations["objective"] == 1 + earlier and res.r_star == r_step
    assert any(f"is the best of {2 + earlier} candidates" in n for n in res.notes), res.notes


def test_an_earlier_level_tying_the_best_step_is_preferred():
    # E_hard is 2 m within 0.003 rad of the last level's answer (which holds the second level's
    # too, 0.0013 away), 1 m elsewhere: the first level's answer ties the best step (60 deg) and
    # is preferred to it.
    e2, _ = bowl(1.3)
    plain = solve(e2, bowl(1.3)[1], (LO, HI), config=SolveConfig(hard_polish=0))
    r0, r1, r2 = (level.r for level in plain.levels)
    assert abs(r1 - r2) < 0.003 < abs(r0 - r2)
    res = solve(e2, lambda r: 1.0 + 1.0 * (jnp.abs(jnp.asarray(r) - r2) < 0.003), (LO, HI),
                config=SolveConfig(hard_polish=0))
    assert res.r_star == r0 and res.E_hard_star == 1.0


def test_a_soft_optimum_tying_the_best_step_on_e_hard_is_kept_without_a_note():
    # E_hard is 1 m everywhere: the soft optimum (1.3) ties the best step (60 deg, the smaller
    # E_soft) and is kept as it is: no other candidate evaluated, no polish move, no note.
    e2, _ = bowl(1.3)
    hard_calls = []
    res = solve(e2, lambda r: hard_calls.append(float(r)) or 1.0, (LO, HI),
                config=SolveConfig(hard_polish=0))
    assert res.r_star == res.levels[-1].r and res.E_hard_star == 1.0 and res.notes == ()
    assert hard_calls[len(res.sweep):] == [res.r_star]


def test_bisection_gradient_nan_inside_its_bracket_is_an_error():
    # Two levels (tol 1/64, then 1/128). The first walks from 0.5 by 1/64, 3/64, 7/64 to the
    # bracket [0.546875, 0.609375] around the minimum 0.6, inside which dE^2/dr is NaN: the
    # first halving point 0.578125 is an error, not an answer (it used to run on to the
    # bracket's end and report the level converged).
    e2 = _bowl_with_nan_gradient(0.6, lambda r: (r > 0.546875) & (r < 0.609375))
    cfg = dataclasses.replace(WALK, tau_schedule=(2.0, 1.0))
    with pytest.raises(FloatingPointError, match=r"not finite in \[0.546875, 0.609375\] \(tau=2.0\)"):
        solve(e2, bowl(0.5)[1], (0.0, 1.0), steps=[0.0, 0.5, 1.0], config=cfg)


def test_bisection_gradient_nan_at_one_halving_point_is_an_error():
    # As above, but dE^2/dr is NaN only at the third halving point 0.6015625: the halvings
    # 0.578125 and 0.59375 (g < 0) narrow the bracket to [0.59375, 0.609375] first.
    e2 = _bowl_with_nan_gradient(0.6, lambda r: r == 0.6015625)
    cfg = dataclasses.replace(WALK, tau_schedule=(2.0, 1.0))
    with pytest.raises(FloatingPointError, match=r"not finite in \[0.59375, 0.609375\]"):
        solve(e2, bowl(0.5)[1], (0.0, 1.0), steps=[0.0, 0.5, 1.0], config=cfg)


@pytest.mark.parametrize("method", ["secant", "bisection"])
@pytest.mark.parametrize("center", [0.004, 0.3, 0.6, 0.999])
def test_no_level_spends_more_than_its_share(method, center):
    # The budget of 12 less the sweep's hard answer and the polish: each level stops at its
    # share, and the whole solve within the budget, wherever the minimum lies.
    e2, e_hard = bowl(center)
    cfg = dataclasses.replace(WALK, method=method, tau_schedule=(4.0, 2.0, 1.0))
    res = solve(e2, e_hard, (0.0, 1.0), steps=[0.0, 0.5, 1.0], config=cfg)
    total = res.evaluations["objective"] + res.evaluations["gradient"]
    assert total <= cfg.max_evaluations and not any("exceed the budget" in n for n in res.notes)
    assert len(res.levels) == 3


def test_result_reports_its_schedule_interval_and_wall_times():
    start = time.perf_counter()
    res = solve(*bowl(1.3), (LO, HI), config=SolveConfig(tau_schedule=(3.0, 1.5)))
    elapsed = time.perf_counter() - start
    assert res.tau_schedule == (3.0, 1.5) and res.interval == (LO, HI)
    assert set(res.wall_s) == {"sweep", "solve"} and min(res.wall_s.values()) >= 0.0
    assert res.wall_s["sweep"] + res.wall_s["solve"] <= elapsed


def test_an_empty_interval_is_refused():
    """lo < hi strictly: [3, 3] holds no r to choose (kills `lo <= hi` in check_interval)."""
    from diffsense.solve._steps import check_interval

    assert check_interval(3, 4) == (3.0, 4.0)
    for lo, hi in ((3.0, 3.0), (4.0, 3.0)):
        with pytest.raises(InputError, match="LO must be smaller than HI"):
            check_interval(lo, hi)


def test_the_least_budget_still_runs_the_first_level():
    # One level and max_evaluations 3, the least SolveConfig accepts: the level's share is
    # 3 - 2 (the answer's hard and soft evaluations) = 1 gradient evaluation, which it spends.
    result = solve(*bowl(0.3), (0.0, 1.0), steps=[0.0, 0.5, 1.0],
                   config=SolveConfig(tau_schedule=(1.0,), hard_polish=0, max_evaluations=3))
    assert [level.gradient_evaluations for level in result.levels] == [1]
    assert result.evaluations["gradient"] == 1
    assert not any("budget spent" in note for note in result.notes)


def _two_centres(r, tau):
    """E^2 = 1 + (r - c)^2 with c = 0.3 at tau 2 and 0.375 (a binary fraction) at tau 1."""
    return 1.0 + (r - jnp.where(tau > 1.5, 0.3, 0.375)) ** 2


def test_bisection_stops_on_an_exact_zero_of_the_gradient():
    # The second level starts at the first's answer near 0.3 and halves its bracket onto 0.375,
    # where dE^2/dr is exactly 0: it stops there, inside the bracket and converged, and the
    # levels' gradient counts add up to the solve's (the second level's count excludes the first's).
    _, e_hard = bowl(0.375)
    config = dataclasses.replace(WALK, tau_schedule=(2.0, 1.0), max_evaluations=30)
    result = solve(_two_centres, e_hard, (0.0, 1.0), steps=[0.0, 0.5, 1.0], config=config)
    last = result.levels[-1]
    assert (last.r, last.bound, last.converged) == (0.375, 0, True)
    assert result.r_star == 0.375
    assert sum(level.gradient_evaluations for level in result.levels) == result.evaluations["gradient"]
