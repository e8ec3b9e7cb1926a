"""The continuation's levels, point by point: the bracket around the best step, the bisection's
walk and halving, the secant's probes, each level's tolerance and share of the budget, and a
gradient that is not finite.

The bisection cases run on (0, 1) with steps 0, 0.5, 1 (bracket (0, 1) around the best step 0.5)
and one level of tol = xtol_rel = 1/128, so every number below is exact in binary: the walk from
0.5 probes 0.5 + tol (1, 3, 7, 15, 31, 63) = 0.5078125, 0.5234375, 0.5546875, 0.6171875,
0.7421875, 0.9921875, then 1.0 (clipped); the level may spend max_evaluations - 2 gradients.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.solve import SolveConfig, solve
from tests._analytic_objectives import HI, LO, bowl

WALK = SolveConfig(method="bisection", tau_schedule=(1.0,), xtol_rel=1 / 128, hard_polish=0,
                   max_evaluations=12)


def _walk(center, max_evaluations, best=0.5):
    e2, _ = bowl(center)
    _, eh = bowl(best)  # the hard objective makes `best` the best step
    cfg = dataclasses.replace(WALK, max_evaluations=max_evaluations)
    res = solve(e2, eh, (0.0, 1.0), steps=[0.0, best, 1.0], config=cfg)
    assert res.bracket == (0.0, 1.0)
    return res.levels[0]


@pytest.mark.parametrize("center, budget, level", [
    # Minimum at 0.6, 4 gradients: g(0.5) and three probes, no sign change yet.
    (0.6, 6, (4, False, 0.5546875, 0)),
    # Minimum beyond 1: the seventh probe is the bracket's end, still downhill.
    (2.0, 10, (8, True, 1.0, 1)),
    # The sign changes between 0.5546875 and 0.6171875 (8 tol); four halvings probe 0.5859375 (-),
    # 0.6015625 (+), 0.59375 (-), 0.59765625 (-): the midpoint of [0.59765625, 0.6015625].
    (0.6, 12, (9, True, 0.599609375, 0)),
    # As above with 7 gradients: the walk's 5 leave 2 halvings: the midpoint of [0.5859375, 0.6015625].
    (0.6, 9, (7, False, 0.59375, 0)),
    # The first probe 0.5078125 is past 0.505: [0.5, 0.5078125] is exactly tol wide, so one
    # halving (0.50390625, -) follows.
    (0.505, 12, (3, True, 0.505859375, 0)),
    # The second probe lands on the minimum (g = 0 closes the bracket from either side), then the
    # two halvings a 2-tol bracket needs: walking up 0.515625 (-), 0.51953125 (-); walking down
    # 0.484375 (+), 0.48046875 (+).
    (0.5234375, 12, (5, True, 0.521484375, 0)),
    (0.4765625, 12, (5, True, 0.478515625, 0)),
])
def test_the_bisection_walks_downhill_then_halves(center, budget, level):
    lv = _walk(center, budget)
    assert (lv.gradient_evaluations, lv.converged, lv.r, lv.bound) == level


def test_a_bracket_narrower_than_tol_needs_no_halving():
    # Best step 1 - tol/4 = 0.998046875, minimum at 0.999: the first probe is clipped to 1.0, the
    # bracket is tol / 4 wide: its midpoint 0.9990234375 is the answer.
    lv = _walk(0.999, 20, best=0.998046875)
    assert (lv.gradient_evaluations, lv.converged, lv.r, lv.bound) == (2, True, 0.9990234375, 0)


def _two_centres(r, tau):
    """E^2 = 1 + (r - c)^2 with c = 0.3 at tau 2 and 0.375 (a binary fraction) at tau 1."""
    return 1.0 + (r - jnp.where(tau > 1.5, 0.3, 0.375)) ** 2


def test_bisection_stops_on_an_exact_zero_of_the_gradient():
    # The second level starts at the first's answer near 0.3 and halves onto 0.375, where
    # dE^2/dr = 0: it stops there, inside the bracket and converged.
    config = dataclasses.replace(WALK, tau_schedule=(2.0, 1.0), max_evaluations=30)
    result = solve(_two_centres, bowl(0.375)[1], (0.0, 1.0), steps=[0.0, 0.5, 1.0], config=config)
    assert (result.levels[-1].r, result.levels[-1].bound, result.levels[-1].converged) == (0.375, 0, True)
    assert result.r_star == 0.375
    assert sum(level.gradient_evaluations for level in result.levels) == result.evaluations["gradient"]


@pytest.mark.parametrize("tau_schedule", [(1.0,), (0.5,)])
def test_a_level_tolerance_is_capped_at_an_eighth_of_the_bracket(tau_schedule):
    # Interval (1, 3), best step 2, bracket (1, 3); xtol = 0.25 x 2 = 0.5 at the last level,
    # whatever its temperature, capped to (3 - 1) / 8 = 0.25. From 2 towards the minimum 2.2:
    # probe 2.25 (+) closes [2, 2.25], one tol wide: one halving at 2.125 (-), answer 2.1875.
    cfg = SolveConfig(method="bisection", tau_schedule=tau_schedule, xtol_rel=0.25, hard_polish=0)
    res = solve(bowl(2.2)[0], bowl(2.0)[1], (1.0, 3.0), steps=[1.0, 2.0, 3.0], config=cfg)
    assert res.bracket == (1.0, 3.0)
    assert (res.levels[0].r, res.levels[0].gradient_evaluations, res.levels[0].converged) == (2.1875, 3, True)


def _float32_level(c):
    """The level, and the points a float32 bisection asks dE^2/dr at for g(r) = r - c on (0, 1)
    from 0.5, with a tolerance (1e-12) far below float32's spacing near 0.5 (~6e-8)."""
    asked = []

    def value_and_grad(r, tau):
        asked.append(r)
        return 1.0 + (r - c) ** 2 / 2.0, r - c

    cfg = SolveConfig(method="bisection", dtype="float32", tau_schedule=(1.0,), xtol_rel=1e-12, hard_polish=0,
                      max_evaluations=200)
    res = solve(bowl(c)[0], bowl(0.5)[1], (0.0, 1.0), steps=[0.0, 0.5, 1.0], config=cfg,
                value_and_grad=value_and_grad)
    level = res.levels[0]
    return level, asked[3:3 + level.gradient_evaluations]  # after the sweep's three steps


@pytest.mark.parametrize("c", [1 / 3, 2 / 3, 0.1, 0.3, 0.45])
def test_a_float32_bisection_asks_no_point_twice(c):
    # Steps below the float32 spacing round back to the start; the halving ends on two
    # neighbouring float32 numbers around c. No evaluation is spent on a point already asked.
    level, asked = _float32_level(c)
    assert len(set(asked)) == level.gradient_evaluations < 198
    assert level.bound == 0 and level.converged
    assert level.r == float(np.float32(level.r)) and abs(level.r - c) <= float(np.spacing(np.float32(c)))


def test_the_float32_walk_doubles_from_the_first_step_that_leaves_the_start():
    # In float32 spacings above 0.5 (2^-24): steps of 2^k 1e-12 round back to 0.5 until k = 15
    # (0.55 spacings), then each doubles: 0.55, 1.1, 2.2, 4.4, 8.8 spacings, on the grid 1, 1, 2,
    # 4, 9: points 1, 2, 4, 8, 17.
    _, asked = _float32_level(0.7)
    assert [(r - 0.5) / 2.0**-24 for r in asked[:6]] == [0.0, 1.0, 2.0, 4.0, 8.0, 17.0]


def _secant_on_the_bowl(config: SolveConfig):
    """The secant on E^2 = 1 + (r - 1.3)^2 through a host value_and_grad: (result, the points
    each temperature's gradient was asked at, in order). e2_soft is then never traced."""
    calls, traced = [], []

    def value_and_grad(r, tau):
        calls.append((r, tau))
        return 1.0 + (r - 1.3) ** 2, 2.0 * (r - 1.3)

    res = solve(lambda r, tau: traced.append(r) or 1.0, bowl(1.3)[1], (LO, HI), config=config,
                value_and_grad=value_and_grad)
    assert traced == [] and [p.E_soft for p in res.sweep] == pytest.approx(
        [np.sqrt(1.0 + (r - 1.3) ** 2) for r in np.deg2rad([30, 60, 90, 120, 150, 180])])
    after_sweep = calls[len(res.sweep):]
    return res, {tau: [r for r, t in after_sweep if t == tau] for tau in config.tau_schedule}


def test_later_levels_probe_near_the_previous_answer():
    # Bracket (30, 90) deg = pi/3 wide. The first level probes a quarter bracket (pi/12) from the
    # best step; the second, warm-started at the first's answer r0 (g > 0: downhill), 1/16 of the
    # bracket (pi/48); the third by the larger of the second level's move and twice its
    # tolerance (tau 2: 2 xtol, so 4 xtol).
    res, points = _secant_on_the_bowl(SolveConfig())
    r0, r1 = res.levels[0].r, res.levels[1].r
    assert points[4.0][:2] == pytest.approx([np.pi / 3, np.pi / 3 + np.pi / 12], abs=1e-12)
    assert points[2.0][:2] == pytest.approx([r0, r0 - np.pi / 48], abs=1e-12)
    xtol = SolveConfig().xtol_rel * (HI - LO)
    assert abs(r1 - r0) < xtol and points[1.0][:2] == pytest.approx([r1, r1 - 4 * xtol], abs=1e-12)


def test_second_level_probes_twice_the_first_tolerance_when_that_is_wider():
    # xtol_rel = 0.006: the first level's tol (tau 4) is 4 x 0.006 x 150 deg = 0.0628 rad; twice
    # that (0.126) beats 1/16 of the bracket (0.065).
    res, points = _secant_on_the_bowl(SolveConfig(xtol_rel=0.006))
    r0 = res.levels[0].r
    assert points[2.0][0] == r0
    assert abs(points[2.0][1] - r0) == pytest.approx(8 * 0.006 * (HI - LO), abs=1e-12)


@pytest.mark.parametrize("method", ["secant", "bisection"])
def test_a_soft_minimum_beyond_the_bracket_ends_on_its_edge(method):
    # E_hard's bowl at 0.6 makes 30 deg the best step (bracket (30, 60) deg); the soft minimum 1.3
    # lies beyond 60 deg: the level ends on that edge (not an end of the interval).
    res = solve(bowl(1.3)[0], bowl(0.6)[1], (LO, HI), config=SolveConfig(method=method))
    assert res.levels[-1].r == pytest.approx(np.pi / 3) and res.levels[-1].bound == 1
    assert not res.on_bound and res.notes


@pytest.mark.parametrize("method", ["secant", "bisection"])
@pytest.mark.parametrize("center", [0.004, 0.3, 0.6, 0.999])
def test_no_level_spends_more_than_its_share(method, center):
    # A budget of 12 for three levels: each stops at its share (a later level keeps 3 back),
    # and the whole solve stays within the budget wherever the minimum lies.
    cfg = dataclasses.replace(WALK, method=method, tau_schedule=(4.0, 2.0, 1.0))
    res = solve(*bowl(center), (0.0, 1.0), steps=[0.0, 0.5, 1.0], config=cfg)
    assert res.evaluations["objective"] + res.evaluations["gradient"] <= cfg.max_evaluations
    assert len(res.levels) == 3


def test_the_least_budget_still_runs_the_first_level():
    # One level and max_evaluations 3, the least SolveConfig accepts: the level's share is
    # 3 - 2 (the answer's hard and soft evaluations) = 1 gradient, which it spends.
    result = solve(*bowl(0.3), (0.0, 1.0), steps=[0.0, 0.5, 1.0],
                   config=SolveConfig(tau_schedule=(1.0,), hard_polish=0, max_evaluations=3))
    assert [level.gradient_evaluations for level in result.levels] == [1]
    assert result.evaluations["gradient"] == 1


def _bowl_with_nan_gradient(center: float, nan_at):
    """E^2 = 1 + (r - center)^2 whose dE^2/dr is NaN where `nan_at(r)` is true."""

    @jax.custom_jvp
    def e2(r, tau):
        del tau
        return 1.0 + (r - center) ** 2

    @e2.defjvp
    def _jvp(primals, tangents):
        r, _ = primals
        return e2(*primals), jnp.where(nan_at(r), jnp.nan, 2.0 * (r - center)) * tangents[0]

    return e2


@pytest.mark.parametrize("center, nan_at, taus, bracket", [
    # Minimum at 0.004: the walk down from 0.5 ends in [0, 0.0078125], where g is NaN throughout.
    (0.004, lambda r: (r > 0.0) & (r < 0.0078125), (1.0,), r"\[0.0, 0.0078125\]"),
    # Two levels: the first walks from 0.5 to [0.546875, 0.609375] around 0.6, NaN inside it.
    (0.6, lambda r: (r > 0.546875) & (r < 0.609375), (2.0, 1.0), r"\[0.546875, 0.609375\]"),
    # NaN only at the third halving point 0.6015625: halvings 0.578125 and 0.59375 (g < 0) first.
    (0.6, lambda r: r == 0.6015625, (2.0, 1.0), r"\[0.59375, 0.609375\]"),
])
def test_a_gradient_not_finite_in_the_bisection_bracket_is_an_error(center, nan_at, taus, bracket):
    cfg = dataclasses.replace(WALK, tau_schedule=taus)
    with pytest.raises(FloatingPointError, match=bracket):
        solve(_bowl_with_nan_gradient(center, nan_at), bowl(0.5)[1], (0.0, 1.0), steps=[0.0, 0.5, 1.0], config=cfg)


@pytest.mark.parametrize("method", ["secant", "bisection"])
def test_a_gradient_not_finite_everywhere_is_an_error(method):
    def e2(r, tau):
        return jnp.sqrt(r - 10.0) + tau  # NaN everywhere on the interval

    with pytest.raises(FloatingPointError):
        solve(e2, lambda r: 1.0, (LO, HI), config=SolveConfig(method=method))
