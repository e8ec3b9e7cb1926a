"""Where each search method lands on analytic objectives whose minimum is known by hand.

tests/test_solve.py checks the solver's guarantees (never worse than the best step, within the
budget); these tests pin the answer itself, for every method: the continuous solve with the
secant and with bisection (each continuation level too), the hard polish, `hard_grid_solve` and
`dense_grid_search`. Interval: HFOV 30..180 deg in radians, steps every 30 deg.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.solve import SolveConfig, dense_grid_search, hard_grid_solve, solve
from tests._analytic_objectives import HI, LO, bowl, dip_at, ripple, staircase

BUDGET = SolveConfig().max_evaluations
XTOL = SolveConfig().xtol_rel * (HI - LO)  # 0.00262 rad = 0.15 deg
METHODS = ("secant", "bisection")
DEG = np.pi / 180.0


def _used(res):
    return res.evaluations["objective"] + res.evaluations["gradient"]


# A bowl's soft minimum is its centre, whatever the temperature: each level must land there
# too, within its own tolerance (xtol * tau / tau_last), not only the final answer.
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("center", [0.6, 1.0, 1.3, 2.2, 3.1])
def test_interior_minimum_of_a_bowl(method, center):
    e2, eh = bowl(center)
    res = solve(e2, eh, (LO, HI), config=SolveConfig(method=method))
    assert abs(res.r_star - center) <= XTOL, res
    assert res.E_hard_star == pytest.approx(1.0, abs=1e-5)  # sqrt(1 + xtol^2) - 1 < 4e-6
    assert not res.on_bound and _used(res) <= BUDGET
    assert sum(lv.gradient_evaluations for lv in res.levels) == res.evaluations["gradient"]
    for level in res.levels:
        assert abs(level.r - center) <= XTOL * level.tau, level
        assert level.bound == 0 and level.converged


@pytest.mark.parametrize("method", METHODS)
def test_a_single_level_lands_from_the_best_step(method):
    # Without the continuation the one level must find 1.3 on its own from the 60-deg step
    # (bisection: bracketing walk then halving; a flipped sign would end on a bracket edge).
    e2, eh = bowl(1.3)
    res = solve(e2, eh, (LO, HI),
                config=SolveConfig(method=method, tau_schedule=(1.0,), hard_polish=0))
    assert abs(res.levels[0].r - 1.3) <= XTOL and abs(res.r_star - 1.3) <= XTOL
    assert res.bracket == pytest.approx((30 * DEG, 90 * DEG))


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("center, end, bound", [(0.2, LO, -1), (4.0, HI, 1)])
def test_minimum_beyond_the_interval_lands_on_its_bound(method, center, end, bound):
    e2, eh = bowl(center)
    res = solve(e2, eh, (LO, HI), config=SolveConfig(method=method))
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
    e2, eh = staircase(1.3)
    res = solve(e2, eh, (LO, HI), config=SolveConfig(method=method))
    assert 1.25 - 1e-9 <= res.r_star < 1.30 and res.E_hard_star == pytest.approx(1.0)
    assert _used(res) <= BUDGET


# Bisection walks and halves where the secant extrapolates: on the ripple (its soft optimum
# moves 0.06 rad between levels) it needs about 30 evaluations to settle each level, against
# 12 for the secant; at the default 20 it stops early, still inside the best basin.
@pytest.mark.parametrize("method, budget", [("secant", 20), ("bisection", 20), ("bisection", 30)])
def test_ripple_continuation_lands_in_the_best_basin(method, budget):
    # Dense 0.5-deg grid reference: the best basin of the rippled bowl (centre 1.3).
    e2, eh = ripple(1.3)
    dense = dense_grid_search(eh, (LO, HI), 0.5 * DEG)
    a, b = dense.basin()
    res = solve(e2, eh, (LO, HI), config=SolveConfig(method=method, max_evaluations=budget))
    assert a <= res.r_star <= b and _used(res) <= budget
    assert sum(lv.gradient_evaluations for lv in res.levels) == res.evaluations["gradient"]
    if method == "secant" or budget == 30:
        assert res.E_hard_star <= dense.E_hard.min() + 1e-4
        assert all(level.converged for level in res.levels)


# The bisection's continuation leaves the polish two probes at the default budget (both miss
# the dip below), so it runs with the polish's evaluations reserved.
@pytest.mark.parametrize("method, reserve", [("secant", False), ("bisection", True)])
def test_polish_lands_in_a_dip_narrower_than_the_soft_objective(method, reserve):
    # Soft bowl at 1.3; E_hard is 0.05 m lower only within 0.01 rad of 1.33. Polish steps from
    # the bracket (30, 90) deg: +-60/16 deg = 0.0654 rad (1.3654, 1.2346: outside), then
    # +30/16 deg = 0.0327 rad: 1.333, inside.
    e2, eh = dip_at(1.33, center=1.3, penalty=0.05)
    res = solve(e2, eh, (LO, HI), config=SolveConfig(method=method, reserve_polish=reserve))
    assert abs(res.r_star - 1.33) <= 0.01 and _used(res) <= BUDGET
    assert res.E_hard_star == pytest.approx(np.sqrt(1.0 + (res.r_star - 1.3) ** 2))
    assert any(n.startswith("hard polish") for n in res.notes)
    # the compass search's third probe (+w/32) is the one taken; its next three do not improve
    width = res.bracket[1] - res.bracket[0]
    assert res.r_star - res.levels[-1].r == pytest.approx(width / 32, abs=1e-12)
    assert res.evaluations["objective"] == 1 + 6 + 1  # E_hard(r_soft), 6 probes, E_soft(r*)


@pytest.mark.parametrize("method", METHODS)
def test_polish_moves_only_on_a_strictly_better_probe(method):
    # E_hard is exactly 1 on a plateau |r - 1.3| < 0.2 and the bowl outside: every polish probe
    # around the soft optimum (steps of 60 deg / 16 = 0.065 rad and less) ties with it.
    e2, eh_bowl = bowl(1.3)

    def eh(r):
        return jnp.where(jnp.abs(jnp.asarray(r) - 1.3) < 0.2, 1.0, eh_bowl(r))

    calls = []
    res = solve(e2, lambda r: calls.append(float(r)) or eh(r), (LO, HI),
                config=SolveConfig(method=method))
    probes = calls[6 + 1:]  # after the six sweep steps and E_hard at the soft optimum
    assert probes, "the polish did not run: nothing was tested"
    assert any(abs(p - 1.3) < 0.2 for p in probes)  # a tying probe was evaluated ...
    assert res.r_star == res.levels[-1].r  # ... and not taken
    assert not any(n.startswith("hard polish") for n in res.notes)


def test_hard_grid_lands_on_its_nearest_inner_point():
    # Best step 60 deg: bracket (30, 90) deg = (pi/6, pi/2), 10 inner points spaced
    # (pi/3) / 11 = 0.0952 rad. Nearest to 1.3: pi/6 + 8 (pi/3) / 11 = 1.28520 (off by 0.0148;
    # the next, 1.38040, is off by 0.080).
    _, eh = bowl(1.3)
    res = hard_grid_solve(eh, (LO, HI), max_evaluations=10)
    assert res.r_star == pytest.approx(np.pi / 6 + 8 * (np.pi / 3) / 11, abs=1e-12)
    assert res.E_hard_star == pytest.approx(np.sqrt(1.0 + 0.014802 ** 2), abs=1e-7)


def test_hard_grid_on_a_bound_and_blind_between_its_points():
    _, eh = bowl(0.2)
    low = hard_grid_solve(eh, (LO, HI), max_evaluations=10)
    assert low.r_star == LO and low.on_bound
    # A 0.02-rad-wide dip at 1.335 lies between the inner points 1.28520 and 1.38040: missed.
    _, eh = dip_at(1.335, center=1.3, penalty=0.5)
    res = hard_grid_solve(eh, (LO, HI), max_evaluations=10)
    assert res.r_star == pytest.approx(np.pi / 6 + 8 * (np.pi / 3) / 11, abs=1e-12)
    assert res.E_hard_star > 1.5


def test_dense_grid_lands_on_the_nearest_half_degree():
    # 1.3 rad = 74.485 deg: the nearest point of the 0.5-deg grid is 74.5 deg.
    _, eh = bowl(1.3)
    dense = dense_grid_search(eh, (LO, HI), 0.5 * DEG)
    assert dense.r[dense.best_index] == pytest.approx(74.5 * DEG, abs=1e-12)
    for center, end in ((0.2, LO), (4.0, HI)):
        d = dense_grid_search(bowl(center)[1], (LO, HI), 0.5 * DEG)
        assert d.r[d.best_index] == end


def test_dense_grid_finds_a_narrow_dip_and_its_side_nearest_the_bowl():
    # Dip of +-0.01 rad (+-0.57 deg) around 1.5 rad = 85.944 deg holds the grid points 85.5 and
    # 86.0 deg; of the two, 85.5 deg is nearer the bowl's centre 1.3 rad.
    _, eh = dip_at(1.5, center=1.3, penalty=0.5)
    dense = dense_grid_search(eh, (LO, HI), 0.5 * DEG)
    assert dense.r[dense.best_index] == pytest.approx(85.5 * DEG, abs=1e-12)
    assert dense.E_hard.min() == pytest.approx(np.sqrt(1.0 + (85.5 * DEG - 1.3) ** 2))


# --- the bisection's walk, step by step -------------------------------------------------------
# Interval (0, 1), steps 0, 0.5, 1 (bracket (0, 1) around the best step 0.5), one level with
# tol = xtol_rel = 1/128 (every number below is exact in binary): the walk from 0.5 probes
# 0.5 + tol * (1, 3, 7, 15, 31, 63) = 0.5078125, 0.5234375, 0.5546875, 0.6171875, 0.7421875,
# 0.9921875, then 1.0 (clipped); the level may spend max_evaluations - 2 gradient evaluations.
def _walk(center, max_evaluations):
    e2, _ = bowl(center)
    _, eh = bowl(0.5)  # the hard objective makes 0.5 the best step
    cfg = SolveConfig(method="bisection", tau_schedule=(1.0,), xtol_rel=1 / 128, hard_polish=0,
                      max_evaluations=max_evaluations)
    res = solve(e2, eh, (0.0, 1.0), steps=[0.0, 0.5, 1.0], config=cfg)
    assert res.bracket == (0.0, 1.0)
    return res.levels[0]


def test_bisection_walk_stops_at_its_budget_share():
    # Minimum at 0.6; 4 evaluations: g(0.5) and three probes, no sign change yet.
    level = _walk(0.6, max_evaluations=6)
    assert level.gradient_evaluations == 4 and not level.converged
    assert level.r == 0.5546875 and level.bound == 0


def test_bisection_walk_reaching_the_bound_with_its_last_probe():
    # Minimum beyond 1: with 8 evaluations the seventh probe is the bracket's end, still downhill.
    level = _walk(2.0, max_evaluations=10)
    assert level.gradient_evaluations == 8 and level.converged
    assert level.r == 1.0 and level.bound == 1


def test_bisection_walk_then_halving():
    # Minimum at 0.6: the sign changes between 0.5546875 and 0.6171875 (8 tol wide). Four
    # halvings probe 0.5859375 (-), 0.6015625 (+), 0.59375 (-), 0.59765625 (-) and leave
    # [0.59765625, 0.6015625] (tol / 2 wide), whose midpoint is the answer.
    level = _walk(0.6, max_evaluations=12)
    assert level.gradient_evaluations == 1 + 4 + 4 and level.converged
    assert level.r == 0.599609375 and level.bound == 0


def test_bisection_halving_capped_by_the_budget():
    # As above with 7 evaluations: the walk's 5 leave 2 halvings, 0.5859375 (-) and 0.6015625
    # (+): the answer is the midpoint of [0.5859375, 0.6015625], not converged.
    level = _walk(0.6, max_evaluations=9)
    assert level.gradient_evaluations == 7 and not level.converged
    assert level.r == 0.59375


def test_bisection_first_probe_brackets_a_tol_wide_interval():
    # Minimum at 0.505: the first probe 0.5078125 is past it: [0.5, 0.5078125] is exactly tol
    # wide, not narrower, so one halving (0.50390625, -) follows: answer 0.505859375.
    level = _walk(0.505, max_evaluations=12)
    assert level.gradient_evaluations == 3 and level.converged
    assert level.r == 0.505859375


@pytest.mark.parametrize("center, answer", [
    # Walking up: g(0.5078125) < 0, g(0.5234375) = 0 closes [0.5078125, 0.5234375] (2 tol);
    # two halvings probe 0.515625 (-), 0.51953125 (-): midpoint of [0.51953125, 0.5234375].
    (0.5234375, 0.521484375),
    # Walking down: g(0.4921875) > 0, g(0.4765625) = 0 closes [0.4765625, 0.4921875]; halvings
    # probe 0.484375 (+), 0.48046875 (+): midpoint of [0.4765625, 0.48046875].
    (0.4765625, 0.478515625),
])
def test_bisection_walk_stops_at_a_probe_with_zero_gradient(center, answer):
    # The second probe lands exactly on the minimum: the walk stops there (an exact zero closes
    # the bracket from either side), then the two halvings a 2-tol-wide bracket needs.
    level = _walk(center, max_evaluations=12)
    assert level.gradient_evaluations == 1 + 2 + 2 and level.converged
    assert level.r == answer and level.bound == 0


def test_bisection_bracket_narrower_than_tol_needs_no_halving():
    # Steps 0, 1 - tol/4, 1 (best: 1 - tol/4 = 0.998046875), minimum at 0.999: the first probe is
    # clipped to 1.0, the bracket is tol / 4 wide: its midpoint 0.9990234375 is the answer.
    e2, _ = bowl(0.999)
    _, eh = bowl(0.998046875)
    cfg = SolveConfig(method="bisection", tau_schedule=(1.0,), xtol_rel=1 / 128, hard_polish=0)
    res = solve(e2, eh, (0.0, 1.0), steps=[0.0, 0.998046875, 1.0], config=cfg)
    level = res.levels[0]
    assert level.gradient_evaluations == 2 and level.converged
    assert level.r == 0.9990234375 and level.bound == 0


def test_bisection_stops_at_a_zero_gradient():
    # Centre exactly on the 90-deg step: dE^2/dr = 0 at the warm start, one evaluation a level.
    center = float(np.deg2rad(90.0))
    e2, eh = bowl(center)
    res = solve(e2, eh, (LO, HI), config=SolveConfig(method="bisection"))
    assert [(lv.r, lv.gradient_evaluations, lv.bound) for lv in res.levels] == [(center, 1, 0)] * 3


def test_bisection_on_a_steep_bowl_keeps_to_its_budget():
    # E^2 = 1 + 1e4 (r - 1.3)^2: the gradient is far from small over the last bracket, yet the
    # halving count (not |dE^2/dr|) decides when the bisection stops.
    def e2(r, tau):
        del tau
        return 1.0 + 1e4 * (r - 1.3) ** 2

    res = solve(e2, lambda r: jnp.sqrt(e2(r, 1.0)), (LO, HI), config=SolveConfig(method="bisection"))
    assert abs(res.r_star - 1.3) <= XTOL and _used(res) <= BUDGET and res.notes == ()
    # the same evaluations as on the shallow bowl: 11 for the first level (walk 5 + halve 5 + 1),
    # then 2 and 3 (bisection does not care how steep)
    assert [lv.gradient_evaluations for lv in res.levels] == [11, 2, 3]
    assert all(abs(lv.r - 1.3) <= XTOL * lv.tau and lv.converged for lv in res.levels)
