"""What the one-parameter solve accepts and refuses, and what it reports: the interval, the sweep's
steps (the paper's grid, round spacings), the sweep itself, `SolveConfig`'s limits (one InputError
each) and the result's fields."""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest

from diffsense.runtime import InputError
from diffsense.solve import (
    PAPER_HFOV_STEPS_DEG,
    SolveConfig,
    check_interval,
    check_steps,
    default_steps,
    hard_grid_solve,
    solve,
    sweep,
)
from tests._analytic_objectives import HI, LO, bowl


def test_default_steps_are_the_papers_grid_and_round_spacings():
    np.testing.assert_allclose(default_steps(30.0, 180.0), PAPER_HFOV_STEPS_DEG)
    np.testing.assert_allclose(default_steps(20.0, 160.0), np.arange(20.0, 161.0, 20.0))
    steps = default_steps(0.3, 1.0)
    assert 6 <= steps.size <= 8 and steps[0] == 0.3 and steps[-1] == 1.0


@pytest.mark.parametrize("lo, hi, counts, expected", [
    # Over [0, 3.75]: 3 steps are 1.875 apart (4 significant digits), 4 steps 1.25 (3): 4 win.
    (0.0, 3.75, (3, 4), [0.0, 1.25, 2.5, 3.75]),
    # Over [0, 5]: 3 steps are 2.5 apart (two digits), 6 steps 1 apart (one): 6 win.
    (0.0, 5.0, (3, 6), [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]),
    (0.0, 5.0, (2,), [0.0, 5.0]),  # the two ends
])
def test_default_steps_prefer_the_roundest_spacing(lo, hi, counts, expected):
    np.testing.assert_array_equal(default_steps(lo, hi, counts=counts), expected)


@pytest.mark.parametrize("counts", [(1,), (), (2, 1)])
def test_fewer_than_two_steps_are_refused(counts):
    with pytest.raises(InputError, match="at least 2"):
        default_steps(0.0, 5.0, counts=counts)


def test_the_interval_is_two_finite_ends_lo_below_hi():
    assert check_interval(3, 4) == (3.0, 4.0)
    for lo, hi in ((3.0, 3.0), (4.0, 3.0)):  # [3, 3] holds no r to choose
        with pytest.raises(InputError, match="LO must be smaller"):
            check_interval(lo, hi)
        with pytest.raises(InputError, match="LO must be smaller"):
            default_steps(lo, hi)
    for lo, hi in ((0.0, math.inf), (-math.inf, 1.0), (math.nan, 1.0), (0.0, math.nan)):
        with pytest.raises(InputError, match="not finite"):
            check_interval(lo, hi)


def test_steps_are_sorted_float64_and_may_touch_the_ends():
    arr = check_steps([[2, 0], [1, 3]], 0.0, 3.0)
    assert arr.dtype == np.float64 and arr.shape == (4,)
    np.testing.assert_array_equal(arr, [0.0, 1.0, 2.0, 3.0])
    np.testing.assert_array_equal(check_steps([0.0, 2.5], 0.0, 2.5), [0.0, 2.5])


@pytest.mark.parametrize("steps, culprit", [
    ([0.0, 1.0, 3.0], "leave the interval"),  # the largest step is checked, wherever it is
    ([3.0, 1.0, 0.0, 2.0], "leave the interval"),
    ([-0.5, 1.0, 2.0], "leave the interval"),
    ([0.0, 1.0, 1.0, 2.0], "repeat"),
    ([1.0], "at least 2"),
    ([0.0, math.nan], "non-finite"),
])
def test_bad_steps_are_refused(steps, culprit):
    with pytest.raises(InputError, match=culprit):
        check_steps(steps, 0.0, 2.5)


def test_solve_and_the_hard_grid_check_the_steps_they_are_given():
    e2, eh = bowl(1.3)
    with pytest.raises(InputError, match="leave the interval"):
        solve(e2, eh, (LO, HI), steps=[0.1, 1.0])
    with pytest.raises(InputError, match="leave the interval"):
        hard_grid_solve(eh, (LO, HI), steps=[0.1, 1.0])


def test_the_sweep_evaluates_hard_and_soft_at_tau_one_by_default():
    seen = []

    def e2_soft(r, tau):
        seen.append(tau)
        return 4.0 * tau + r

    points = sweep(lambda r: 10.0 * r, e2_soft, [[0.0, 5.0], [12.0, 21.0]])
    assert seen == [1.0] * 4
    assert [(p.r, p.E_soft, p.E_hard) for p in points] == [
        (0.0, 2.0, 0.0), (5.0, 3.0, 50.0), (12.0, 4.0, 120.0), (21.0, 5.0, 210.0)]


def test_the_solves_sweep_reports_e_soft_at_the_last_temperature():
    # E^2 = tau + (r - 1.3)^2 under the schedule (2, 0.5): the sweep reports E_soft at tau = 0.5.
    steps = np.deg2rad([30.0, 60.0, 90.0, 120.0, 150.0, 180.0])
    res = solve(*bowl(1.3), (LO, HI), steps=steps, config=SolveConfig(tau_schedule=(2.0, 0.5)),
                value_and_grad=lambda r, tau: (tau + (r - 1.3) ** 2, 2.0 * (r - 1.3)))
    assert [p.E_soft for p in res.sweep] == pytest.approx(np.sqrt(0.5 + (steps - 1.3) ** 2))


@pytest.mark.parametrize("kwargs, culprit", [
    (dict(tau_schedule=(1.0, 2.0)), "tau_schedule"),  # must not increase
    (dict(tau_schedule=(0.0,)), "tau_schedule"),
    (dict(tau_schedule=(1.0, -1.0)), "tau_schedule"),
    (dict(tau_schedule=(math.inf, 1.0)), "tau_schedule"),
    (dict(tau_schedule=()), "tau_schedule"),
    (dict(xtol_rel=0.0), "xtol_rel"),
    (dict(xtol_rel=0.5), "xtol_rel"),
    (dict(hard_polish=-1), "hard_polish"),
    # The least budget of 3 levels: 1 gradient + 3 reserved for each later level + the answer's
    # hard and soft evaluations = 9; with the 6 polish evaluations reserved, 15.
    (dict(max_evaluations=8), "need at least 9"),
    (dict(max_evaluations=14, reserve_polish=True), "need at least 15"),
    (dict(tau_schedule=(1.0,), max_evaluations=2), "need at least 3"),
])
def test_a_bad_solve_config_is_one_input_error(kwargs, culprit):
    with pytest.raises(InputError, match=culprit):
        SolveConfig(**kwargs)


def test_the_edges_of_solve_config_are_accepted():
    SolveConfig(tau_schedule=(2.0, 2.0, 1.0))  # equal temperatures may repeat
    SolveConfig(xtol_rel=0.49)
    SolveConfig(max_evaluations=9)
    SolveConfig(max_evaluations=15, reserve_polish=True)


def test_the_result_reports_its_schedule_interval_and_wall_times_and_is_json_ready():
    start = time.perf_counter()
    res = solve(*bowl(1.3), (LO, HI), config=SolveConfig(tau_schedule=(3, 1.5)))
    elapsed = time.perf_counter() - start
    assert res.tau_schedule == (3.0, 1.5) and all(type(t) is float for t in res.tau_schedule)
    assert res.interval == (LO, HI)
    assert set(res.wall_s) == {"sweep", "solve"} and min(res.wall_s.values()) >= 0.0
    assert res.wall_s["sweep"] + res.wall_s["solve"] <= elapsed
    d = json.loads(json.dumps(res.to_dict()))
    assert d["r_star"] == res.r_star and d["evaluations"] == res.evaluations
    assert [p["r"] for p in d["sweep"]] == [p.r for p in res.sweep]
    assert [lv["tau"] for lv in d["levels"]] == [3.0, 1.5]
    assert solve(*bowl(1.3), (LO, HI), sweep_points=res.sweep).sweep == res.sweep  # a sweep given is reused
