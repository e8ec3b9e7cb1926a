"""The sweep's step checks and the sweep itself (`diffsense/solve/_steps.py`), by hand (survivors
of a complete mutation run of the file, docs/mutation.md)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from diffsense.runtime._errors import InputError
from diffsense.solve import default_steps, sweep
from diffsense.solve._steps import check_interval, check_steps


@pytest.mark.parametrize("lo, hi", [(0.0, math.inf), (-math.inf, 1.0), (math.nan, 1.0), (0.0, math.nan)])
def test_an_interval_with_one_infinite_or_nan_end_is_refused(lo, hi):
    with pytest.raises(InputError, match="not finite"):
        check_interval(lo, hi)


def test_check_steps_returns_sorted_float64_of_any_shape():
    arr = check_steps([[2, 0], [1, 3]], 0.0, 3.0)
    assert arr.dtype == np.float64 and arr.shape == (4,)
    np.testing.assert_array_equal(arr, [0.0, 1.0, 2.0, 3.0])


def test_check_steps_accepts_the_interval_ends_and_refuses_beyond_them():
    np.testing.assert_array_equal(check_steps([0.0, 2.5], 0.0, 2.5), [0.0, 2.5])
    # The largest step is checked, not the second or the second largest: 3 > 2.5.
    for steps in ([0.0, 1.0, 3.0], [3.0, 1.0, 0.0, 2.0], [-0.5, 1.0, 2.0]):
        with pytest.raises(InputError, match="leave the interval"):
            check_steps(steps, 0.0, 2.5)


def test_check_steps_refuses_a_repeated_step():
    with pytest.raises(InputError, match="repeat a value"):
        check_steps([0.0, 1.0, 1.0, 2.0], 0.0, 2.0)


def test_default_steps_prefers_the_rounder_spacing_over_fewer_steps():
    # Over [0, 3.75]: 3 steps are 1.875 apart (4 significant digits), 4 steps 1.25 (3): 4 win.
    np.testing.assert_array_equal(default_steps(0.0, 3.75, counts=(3, 4)), [0.0, 1.25, 2.5, 3.75])


def test_sweep_evaluates_the_soft_objective_at_tau_1_by_default():
    seen = []

    def e2_soft(r, tau):
        seen.append(tau)
        return 4.0 * tau + r

    points = sweep(lambda r: 10.0 * r, e2_soft, [[0.0, 5.0], [12.0, 21.0]])
    assert seen == [1.0] * 4
    assert [p.r for p in points] == [0.0, 5.0, 12.0, 21.0]
    assert [p.E_soft for p in points] == [2.0, 3.0, 4.0, 5.0]
    assert [p.E_hard for p in points] == [0.0, 50.0, 120.0, 210.0]
