"""The answer says what it is: near-optimal intervals and the pressing-on-bound and flat flags."""

from __future__ import annotations

import pytest

from diffsense.solve._answer import explain, near_optimal


def test_an_interior_sharp_minimum_has_no_flags():
    pts = [(r, abs(r - 50.0) + 10.0) for r in range(30, 181, 10)]
    out = near_optimal(pts, 30.0, 180.0, 50.0)
    assert out["flags"] == [] and out["near_optimal"]["intervals"] == [[50, 50]]
    assert out["near_optimal"]["tolerance_m"] == pytest.approx(0.05)  # 0.5 % of 10 m


def test_a_minimum_at_the_bound_presses_on_it():
    pts = [(r, r / 10.0) for r in (0.01, 30.0, 60.0, 360.0)]
    out = near_optimal(pts, 0.01, 360.0, 0.01)
    assert out["flags"] == ["pressing_on_bound"]
    assert "widen the interval" in explain(out["flags"], [], "deg")[0]
    inside = near_optimal(pts, 0.01, 360.0, 0.01 + 0.021 * 359.99)  # beyond 2 % of the width
    assert "pressing_on_bound" not in inside["flags"]


def test_a_flat_tail_is_flagged_with_its_interval():
    # E flat (to 1 mm) from 200 m on, as the radar's range objective is above its SNR-limited range.
    pts = [(r, 20.0 if r >= 200 else 20.0 + (200 - r) / 10.0) for r in range(50, 1001, 50)]
    pts = [(r, e + (0.001 if r == 600 else 0.0)) for r, e in pts]
    out = near_optimal(pts, 0.1, 1000.0, 336.0)
    assert out["flags"] == ["flat"] and out["near_optimal"]["intervals"] == [[200, 1000]]
    assert "[200, 1000] m" in explain(out["flags"], out["near_optimal"]["intervals"], "m")[0]


def test_two_separate_near_optimal_intervals():
    pts = [(0.0, 1.0), (1.0, 5.0), (2.0, 1.001), (3.0, 1.002), (4.0, 9.0)]
    out = near_optimal(pts, 0.0, 4.0, 2.0)
    assert out["near_optimal"]["intervals"] == [[0.0, 0.0], [2.0, 3.0]]
    assert "flat" in out["flags"]  # [2, 3] is 25 % of the width
