"""What the gradient-free searches report, pinned: hard_grid_solve's result fields and
basin_check's edges and reasons (from the solve package's mutation survivors)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from diffsense.solve import DenseGrid, SolveConfig, basin_check, hard_grid_solve, solve
from tests._analytic_objectives import HI, LO, bowl, dip_at


def test_hard_grid_solve_reports_a_hard_only_search():
    _, eh = bowl(1.3)
    res = hard_grid_solve(eh, (LO, HI))  # the default budget: 20 inner points
    assert res.evaluations == {"objective": 20, "gradient": 0}
    assert res.E_soft_star == res.E_hard_star  # no soft objective: E_soft holds E_hard
    for p in res.sweep:
        assert p.E_soft == pytest.approx(p.E_hard, rel=1e-12)
    assert res.tau_schedule == () and res.levels == () and res.interval == (LO, HI)
    assert len(res.notes) == 1 and res.notes[0].startswith("hard estimator: no gradient")
    assert "of 20 points inside the best bracket" in res.notes[0]
    assert set(res.wall_s) == {"sweep", "solve"} and all(t >= 0 for t in res.wall_s.values())


def test_hard_grid_solve_uses_the_given_steps():
    # Steps 40, 100, 160 deg: best 100 deg (1.745 rad, nearest 1.3), bracket (40, 160) deg.
    _, eh = bowl(1.3)
    steps = np.deg2rad([40.0, 100.0, 160.0])
    res = hard_grid_solve(eh, (LO, HI), steps=steps, max_evaluations=5)
    assert [p.r for p in res.sweep] == pytest.approx(list(steps))
    assert res.bracket == pytest.approx((steps[0], steps[2]))
    # inner points 40 + 20 k deg, k = 1..5: 60, 80, 100, 120, 140 deg; nearest 1.3 rad: 80 deg
    assert res.r_star == pytest.approx(math.radians(80.0))


# A grid r = 0, 0.5, ..., 4 (spacing 0.5, exact in binary): best r = 2.0 (E 1.0); E rises from
# it to r = 1.5 on the left (then falls) and to r = 3.0 on the right: the basin is [1.5, 3.0].
def _grid():
    r = 0.5 * np.arange(9)
    e = np.array([3.0, 2.0, 1.1, 1.2, 1.0, 1.1, 1.5, 1.4, 2.0])
    return DenseGrid(r=r, E_hard=e, evaluations=9, wall_s=0.0)


@pytest.mark.parametrize("r_star, inside", [(1.25, True), (1.24, False), (3.25, True),
                                            (3.26, False), (2.0, True)])
def test_basin_check_accepts_half_a_spacing_around_the_basin(r_star, inside):
    dense = _grid()
    assert dense.basin() == (1.5, 3.0)
    # within 0.25 (half the spacing) of [1.5, 3.0], edges included
    reason = basin_check(dense, r_star)
    assert (reason is None) is inside, reason


def test_basin_check_reasons():
    dense = _grid()
    equal = basin_check(dense, 0.5, 1.0)
    assert "at least as deep (E_hard=1 m)" in equal
    worse = basin_check(dense, 0.5, 1.25, bracket=(0.0, 1.0))
    assert "worse by 0.25 m" in worse and "does not bracket" in worse
    for bracket in ((2.0, 3.5), (0.0, 2.0)):  # the best point on either edge is inside
        assert "inside the bracket" in basin_check(dense, 0.5, 1.25, bracket=bracket)
    two = DenseGrid(r=np.array([0.0, 1.0]), E_hard=np.array([2.0, 1.0]), evaluations=2, wall_s=0.0)
    assert basin_check(two, 0.4) is None and basin_check(two, 0.6) is None  # basin [0, 1]
    assert basin_check(two, 1.49) is None and basin_check(two, 1.51) is not None
    one = DenseGrid(r=np.array([1.0]), E_hard=np.array([1.0]), evaluations=1, wall_s=0.0)
    assert basin_check(one, 1.0) is None and basin_check(one, 1.001) is not None


def test_solve_result_to_dict_is_plain_and_complete():
    import json

    _, eh = bowl(1.3)
    res = hard_grid_solve(eh, (LO, HI), max_evaluations=3)
    d = res.to_dict()
    assert d["r_star"] == res.r_star and d["evaluations"] == {"objective": 3, "gradient": 0}
    assert [p["r"] for p in d["sweep"]] == [p.r for p in res.sweep]
    json.dumps(d)  # JSON-ready


def test_solve_config_edges():
    from diffsense.runtime._errors import InputError
    from diffsense.solve import SolveConfig

    SolveConfig(tau_schedule=(2.0, 2.0, 1.0))  # equal temperatures may repeat
    SolveConfig(xtol_rel=0.49)
    with pytest.raises(InputError, match="xtol_rel"):
        SolveConfig(xtol_rel=0.5)
    # The least budget of 3 levels: 1 gradient + 3 reserved for each later level + the final
    # hard and soft evaluations = 1 + 6 + 2 = 9; with the 6 polish evaluations reserved, 15.
    SolveConfig(max_evaluations=9)
    with pytest.raises(InputError, match="need at least 9"):
        SolveConfig(max_evaluations=8)
    SolveConfig(max_evaluations=15, reserve_polish=True)
    with pytest.raises(InputError, match="need at least 15"):
        SolveConfig(max_evaluations=14, reserve_polish=True)


def test_soft_e_below_one_metre_is_its_square_root():
    # E^2 = 0.25 + (r - 1.3)^2: E_soft at the answer is 0.5 m (the square root is floored at 0,
    # not at 1).
    from diffsense.solve import solve

    def e2(r, tau):
        del tau
        return 0.25 + (r - 1.3) ** 2

    res = solve(e2, lambda r: math.sqrt(0.25 + (float(r) - 1.3) ** 2), (LO, HI))
    assert res.E_soft_star == pytest.approx(0.5, abs=1e-5)


def test_the_hard_polish_note_names_the_answer_objective_and_both_points():
    e2, eh = dip_at(1.33, center=1.3, penalty=0.05)
    plain = solve(e2, eh, (LO, HI), config=SolveConfig(hard_polish=0), answer_name="E_ref")
    res = solve(e2, eh, (LO, HI), answer_name="E_ref")
    (note,) = [n for n in res.notes if n.startswith("hard polish")]
    assert note == (f"hard polish: r={plain.r_star:.6g} -> {res.r_star:.6g} lowered E_ref from "
                    f"{plain.E_hard_star:.6g} to {res.E_hard_star:.6g} m (the soft objective cannot resolve "
                    f"differences this fine)")
