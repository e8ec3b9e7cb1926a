"""result.json's "near_optimal" and "flags" beside r* (`diffsense.solve.near_optimal`, `explain`),
pinned to values worked out by hand: 1 cm or 0.5 % of the best E, 2 % of the width from a bound,
10 % of it flat. Plain Python on small hand-built inputs: no program is compiled."""

from __future__ import annotations

import math

import pytest

from diffsense.solve import explain, near_optimal


@pytest.mark.parametrize("best, tol", [(1.0, 0.01), (2.0, 0.01), (10.0, 0.05), (50.0, 0.25)])
def test_the_tolerance_is_the_larger_of_1_cm_and_half_a_percent(best, tol):
    out = near_optimal([(0.0, best + 5.0), (1.0, best), (2.0, best + 5.0)], 0.0, 2.0, 1.0)
    assert out["near_optimal"]["tolerance_m"] == pytest.approx(tol, rel=1e-12)


def test_a_point_exactly_at_the_tolerance_is_near_optimal_and_one_just_past_it_is_not():
    best = 10.0
    edge = best + max(0.01, 0.005 * best)
    pts = [(5.0, edge), (4.0, best), (3.0, math.nextafter(edge, math.inf)), (2.0, edge), (1.0, 99.0)]
    out = near_optimal(pts, 0.0, 100.0, 4.0)  # given unsorted: the intervals follow r
    assert out["near_optimal"]["intervals"] == [[2.0, 2.0], [4.0, 5.0]]


def test_intervals_open_and_close_with_the_runs():
    pts = [(float(r), e) for r, e in enumerate([1.0, 1.0, 3.0, 3.0, 1.0, 3.0, 1.0, 1.0, 1.0])]
    out = near_optimal(pts, 0.0, 80.0, 6.0)
    assert out["near_optimal"]["intervals"] == [[0.0, 1.0], [4.0, 4.0], [6.0, 8.0]]
    assert out["flags"] == []  # 6 from a bound (> 1.6) in an interval 2 wide (< 8)


@pytest.mark.parametrize("side", ["lo", "hi"])
def test_pressing_on_bound_at_exactly_two_percent_of_the_width(side):
    lo, hi = 10.0, 60.0  # width 50: 2 % is 1.0, exact in binary (of hi + lo, it would be 1.4)
    at = lo + 1.0 if side == "lo" else hi - 1.0
    past = lo + 1.2 if side == "lo" else hi - 1.2
    pts = [(lo, 5.0), (20.0, 6.0), (35.0, 7.0), (hi, 8.0)]
    assert "pressing_on_bound" in near_optimal(pts, lo, hi, at)["flags"]
    assert "pressing_on_bound" not in near_optimal(pts, lo, hi, past)["flags"]


def test_flat_needs_the_interval_holding_r_star_to_span_ten_percent():
    lo, hi = 0.0, 80.0  # 10 % of the width is 8.0
    pts = [(20.0, 9.0), (30.0, 1.0), (38.0, 1.0), (50.0, 9.0), (60.0, 1.0), (70.0, 1.0), (79.0, 9.0)]
    # [30, 38] spans exactly 8: flat when r* lies in it, ends included.
    for r_star in (30.0, 34.0, 38.0):
        assert near_optimal(pts, lo, hi, r_star)["flags"] == ["flat"]
    # [60, 70] spans 10 but does not hold r* = 34 or 45; r* = 45 lies in no interval.
    assert near_optimal(pts, lo, hi, 45.0)["flags"] == []
    narrow = [(20.0, 9.0), (30.0, 1.0), (37.5, 1.0), (50.0, 9.0)]
    assert near_optimal(narrow, lo, hi, 34.0)["flags"] == []


def test_explain_gives_one_line_per_flag_with_the_flat_intervals_in_the_unit():
    assert explain([], [[1.0, 2.0]], "deg") == []
    (bound,) = explain(["pressing_on_bound"], [], "deg")
    (flat,) = explain(["flat"], [[30.0, 38.123456], [60.0, 70.0]], "deg")
    assert "bound" in bound and "[30, 38.12] deg, [60, 70] deg" in flat
    assert explain(["pressing_on_bound", "flat"], [[0.0, 10.0]], "m")[0] == bound  # in the flags' order
    assert near_optimal([(0.0, 1.0), (5.0, 1.0), (10.0, 1.0), (100.0, 9.0)], 0.0, 100.0, 0.0)["flags"] == [
        "pressing_on_bound", "flat"]
    assert "[0, 10] is" in explain(["flat"], [[0.0, 10.0]], "")[0]  # no unit: no space for one
