"""The gradient-free searches, where they land by hand: the dense grid (the brute-force baseline)
and its basin check, and `hard_grid_solve` (the hard estimator's search: the sweep, then an even
grid inside the best step's bracket)."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from diffsense.runtime import InputError
from diffsense.solve import (
    DenseGrid,
    SolveConfig,
    basin_check,
    dense_grid_search,
    hard_grid_solve,
    solve,
)
from tests._analytic_objectives import HI, LO, STEP_W, bowl, dip_at, ripple, staircase

DEG = np.pi / 180.0
# Best step 60 deg: bracket (30, 90) deg = (pi/6, pi/2), 10 inner points spaced (pi/3) / 11 =
# 0.0952 rad. Nearest to 1.3: pi/6 + 8 (pi/3) / 11 = 1.28520 (off by 0.0148; the next, 1.38040,
# is off by 0.080).
NEAREST_INNER = np.pi / 6 + 8 * (np.pi / 3) / 11


def _slow_bowl(seconds: float):
    def e_hard(r):
        time.sleep(seconds)
        return (r - 0.35) ** 2
    return e_hard


def test_the_dense_grid_lands_on_the_nearest_half_degree():
    # 1.3 rad = 74.485 deg: the nearest point of the 0.5-deg grid (301 points) is 74.5 deg.
    dense = dense_grid_search(bowl(1.3)[1], (LO, HI), 0.5 * DEG)
    assert dense.evaluations == dense.r.size == 301 and (dense.r[0], dense.r[-1]) == (LO, HI)
    assert dense.r[dense.best_index] == pytest.approx(74.5 * DEG, abs=1e-12)
    for center, end in ((0.2, LO), (4.0, HI)):
        d = dense_grid_search(bowl(center)[1], (LO, HI), 0.5 * DEG)
        assert d.r[d.best_index] == end


def test_the_dense_grid_finds_a_narrow_dip_on_its_side_nearest_the_bowl():
    # A dip of +-0.01 rad around 1.5 rad = 85.944 deg holds the grid points 85.5 and 86.0 deg;
    # of the two, 85.5 deg is nearer the bowl's centre 1.3 rad.
    dense = dense_grid_search(dip_at(1.5, center=1.3, penalty=0.5)[1], (LO, HI), 0.5 * DEG)
    assert dense.r[dense.best_index] == pytest.approx(85.5 * DEG, abs=1e-12)
    assert dense.E_hard.min() == pytest.approx(np.sqrt(1.0 + (85.5 * DEG - 1.3) ** 2))


def test_the_dense_grid_ends_on_the_interval_and_times_its_evaluations():
    # (0, 1) every 0.3: 0, 0.3, 0.6, 0.9 and the end 1 (the last spacing shorter); 5 calls of
    # at least 2 ms each.
    dense = dense_grid_search(_slow_bowl(0.002), (0.0, 1.0), 0.3)
    np.testing.assert_allclose(dense.r, [0.0, 0.3, 0.6, 0.9, 1.0], rtol=0, atol=1e-15)
    assert dense.evaluations == 5 and 0.010 <= dense.wall_s < 5.0
    for step in (0.0, -0.1, math.nan):
        with pytest.raises(InputError, match="step"):
            dense_grid_search(bowl(1.3)[1], (LO, HI), step)


def test_the_basin_includes_plateaus():
    # The staircase's best plateau [1.25, 1.30) and the rising steps on both sides.
    dense = dense_grid_search(staircase(1.3)[1], (1.0, 1.6), STEP_W / 5)
    assert dense.basin() == (pytest.approx(1.0), pytest.approx(1.6))


# A grid r = 0, 0.5, ..., 4 (spacing 0.5, exact in binary): best r = 2.0 (E 1.0); E rises from
# it to r = 1.5 on the left (then falls) and to r = 3.0 on the right: the basin is [1.5, 3.0].
def _grid():
    e = np.array([3.0, 2.0, 1.1, 1.2, 1.0, 1.1, 1.5, 1.4, 2.0])
    return DenseGrid(r=0.5 * np.arange(9), E_hard=e, evaluations=9, wall_s=0.0)


@pytest.mark.parametrize("r_star, inside", [(1.25, True), (1.24, False), (3.25, True), (3.26, False), (2.0, True)])
def test_the_basin_check_accepts_half_a_spacing_around_the_basin(r_star, inside):
    dense = _grid()
    assert dense.basin() == (1.5, 3.0)
    assert (basin_check(dense, r_star) is None) is inside


def test_the_basin_check_of_a_grid_of_one_or_two_points():
    two = DenseGrid(r=np.array([0.0, 1.0]), E_hard=np.array([2.0, 1.0]), evaluations=2, wall_s=0.0)
    assert basin_check(two, 0.4) is None and basin_check(two, 0.6) is None  # basin [0, 1]
    assert basin_check(two, 1.49) is None and basin_check(two, 1.51) is not None
    one = DenseGrid(r=np.array([1.0]), E_hard=np.array([1.0]), evaluations=1, wall_s=0.0)
    assert basin_check(one, 1.0) is None and basin_check(one, 1.001) is not None


def test_the_basin_check_says_why_an_answer_misses():
    # Outside the basin [1.5, 3] of the best point r = 2 (E 1 m): in another basin as deep; worse,
    # with a bracket that holds the best point (the soft objective misses it) or not (the steps
    # are coarser than the basin; the best point on a bracket's edge is inside it).
    dense = _grid()
    assert "at least as deep" in basin_check(dense, 0.5, 1.0)
    assert "worse by 0.25 m" in basin_check(dense, 0.5, 1.25)
    assert "does not bracket" in basin_check(dense, 0.5, 1.25, bracket=(0.0, 1.0))
    for bracket in ((2.0, 3.5), (0.0, 2.0)):
        assert "misses the hard basin" in basin_check(dense, 0.5, 1.25, bracket=bracket)


def test_the_solve_lands_in_the_dense_grids_basin():
    # The staircase and the rippled bowl (whose ripples a single temperature gets stuck in).
    for (e2, eh), margin in ((staircase(1.3), 1e-12), (ripple(1.3), 1e-4)):
        dense = dense_grid_search(eh, (LO, HI), 0.5 * DEG)
        res = solve(e2, eh, (LO, HI))
        assert basin_check(dense, res.r_star, res.E_hard_star, res.bracket) is None
        assert res.E_hard_star <= dense.E_hard.min() + margin
    # the last of them, the ripple, at one temperature (no polish, which hops basins): outside it
    single = solve(e2, eh, (LO, HI), config=SolveConfig(tau_schedule=(1.0,), hard_polish=0))
    assert basin_check(dense, single.r_star, single.E_hard_star) is not None


def test_the_hard_grid_lands_on_its_nearest_inner_point():
    calls = []
    _, eh = bowl(1.3)
    res = hard_grid_solve(lambda r: calls.append(float(r)) or eh(r), (LO, HI), max_evaluations=10)
    assert res.r_star == pytest.approx(NEAREST_INNER, abs=1e-12)
    assert res.E_hard_star == pytest.approx(np.sqrt(1.0 + 0.014802 ** 2), abs=1e-7)
    # the sweep (E_hard, and E_soft = E_hard^2 from it) then 10 points strictly inside the bracket
    assert len(calls) == 2 * len(res.sweep) + 10 and res.evaluations == {"objective": 10, "gradient": 0}
    assert all(res.bracket[0] < r < res.bracket[1] for r in calls[-10:])


def test_the_hard_grid_on_a_bound_and_blind_between_its_points():
    low = hard_grid_solve(bowl(0.2)[1], (LO, HI), max_evaluations=10)
    assert low.r_star == LO and low.on_bound
    # A 0.02-rad-wide dip at 1.335 lies between the inner points 1.28520 and 1.38040: missed.
    res = hard_grid_solve(dip_at(1.335, center=1.3, penalty=0.5)[1], (LO, HI), max_evaluations=10)
    assert res.r_star == pytest.approx(NEAREST_INNER, abs=1e-12) and res.E_hard_star > 1.5


def test_the_hard_grid_reports_a_hard_only_search():
    res = hard_grid_solve(bowl(1.3)[1], (LO, HI))  # the default budget: 20 inner points
    assert res.evaluations == {"objective": 20, "gradient": 0}
    assert res.E_soft_star == res.E_hard_star  # no soft objective: E_soft holds E_hard
    assert all(p.E_soft == pytest.approx(p.E_hard, rel=1e-12) for p in res.sweep)
    assert res.tau_schedule == () and res.levels == () and res.interval == (LO, HI) and len(res.notes) == 1
    assert set(res.wall_s) == {"sweep", "solve"}


def test_the_hard_grid_uses_the_given_steps_and_times_both_phases():
    # Steps 40, 100, 160 deg: best 100 deg (nearest 1.3 rad), bracket (40, 160) deg; inner points
    # 60, 80, 100, 120, 140 deg: nearest 1.3 rad is 80 deg.
    steps = np.deg2rad([40.0, 100.0, 160.0])
    res = hard_grid_solve(bowl(1.3)[1], (LO, HI), steps=steps, max_evaluations=5)
    assert [p.r for p in res.sweep] == pytest.approx(list(steps))
    assert res.bracket == pytest.approx((steps[0], steps[2])) and res.r_star == pytest.approx(math.radians(80.0))
    # 6 sweep steps and 4 inner points, each call at least 2 ms
    timed = hard_grid_solve(_slow_bowl(0.002), (0.0, 1.0), steps=np.linspace(0.0, 1.0, 6), max_evaluations=4)
    assert 0.012 <= timed.wall_s["sweep"] < 5.0 and 0.008 <= timed.wall_s["solve"] < 5.0
