"""The gradient-free searches and the sweep's steps, pinned by hand (survivors of a partial
solve mutation run, docs/mutation.md): the dense grid's points and timing, the hard grid
solve's timing, the basin check's words for an equally deep minimum, and the step counts
`default_steps` accepts and chooses."""

from __future__ import annotations

import time

import numpy as np
import pytest

from diffsense.runtime._errors import InputError
from diffsense.solve import DenseGrid, basin_check, default_steps, dense_grid_search, hard_grid_solve


def _slow_bowl(seconds: float):
    def e_hard(r):
        time.sleep(seconds)
        return (r - 0.35) ** 2
    return e_hard


def test_dense_grid_ends_on_the_interval_and_times_its_evaluations():
    # (0, 1) every 0.3: 0, 0.3, 0.6, 0.9 and the end 1 (the last spacing shorter); 5 calls of
    # at least 2 ms each.
    dense = dense_grid_search(_slow_bowl(0.002), (0.0, 1.0), 0.3)
    np.testing.assert_allclose(dense.r, [0.0, 0.3, 0.6, 0.9, 1.0], rtol=0, atol=1e-15)
    assert dense.evaluations == 5
    assert 0.010 <= dense.wall_s < 5.0


def test_hard_grid_solve_times_its_sweep_and_its_inner_grid():
    # 6 sweep steps and 4 inner points, each call at least 2 ms.
    res = hard_grid_solve(_slow_bowl(0.002), (0.0, 1.0), steps=np.linspace(0.0, 1.0, 6), max_evaluations=4)
    assert 0.012 <= res.wall_s["sweep"] < 5.0
    assert 0.008 <= res.wall_s["solve"] < 5.0


def test_basin_check_names_an_equally_deep_minimum():
    # E_hard = 1 2 1 at r = 0, 1, 2: the best point r = 0 (the first of the ties), its basin
    # [0, 1] (E never falls walking out of it); r* = 2, 1.5 spacings past it, has the same E_hard.
    dense = DenseGrid(r=np.arange(3.0), E_hard=np.array([1.0, 2.0, 1.0]), evaluations=3, wall_s=0.0)
    assert basin_check(dense, 2.0, 1.0) == (
        "r*=2 lies outside the basin [0, 1] of the best dense point r=0 (E_hard=1 m), in another "
        "basin at least as deep (E_hard=1 m): the hard objective has several equally good minima"
    )


def test_default_steps_counts():
    # Over [0, 5]: 3 steps are 2.5 apart (two significant digits), 6 steps 1 apart (one): 6 win.
    np.testing.assert_array_equal(default_steps(0.0, 5.0, counts=(3, 6)), [0.0, 1.0, 2.0, 3.0, 4.0, 5.0])
    np.testing.assert_array_equal(default_steps(0.0, 5.0, counts=(2,)), [0.0, 5.0])  # the two ends
    for counts in ((1,), (), (2, 1)):
        with pytest.raises(InputError, match="at least 2"):
            default_steps(0.0, 5.0, counts=counts)
