"""What the main job tells the user beside r*, pinned to values worked out by hand: the answer's
near-optimal set and flags, and the parameter names and bounds a problem accepts.

E's breakdown and the predictor's domain guard are pinned in tests/test_breakdown_pinned.py.
Everything here is plain Python on small hand-built inputs: no program is compiled.
"""

from __future__ import annotations

import math

import pytest

from diffsense.solve._answer import (
    BOUND_FRACTION,
    FLAT_FRACTION,
    NEAR_OPTIMAL_ABS_M,
    NEAR_OPTIMAL_REL,
    explain,
    near_optimal,
)
from diffsense.sensors._names import _finite, _resolve_params, resolve_name
from diffsense.runtime._errors import InputError
from diffsense.sensors import Camera, Radar, Suite


def test_the_answer_constants():
    # 1 cm absolute, 0.5 % relative; 2 % of the width from a bound; 10 % of it flat.
    assert (NEAR_OPTIMAL_ABS_M, NEAR_OPTIMAL_REL, BOUND_FRACTION, FLAT_FRACTION) == (0.01, 0.005, 0.02, 0.10)


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


def test_flat_and_pressing_together_keep_their_order():
    pts = [(0.0, 1.0), (5.0, 1.0), (10.0, 1.0), (100.0, 9.0)]
    assert near_optimal(pts, 0.0, 100.0, 0.0)["flags"] == ["pressing_on_bound", "flat"]


def test_explain_words_each_flag():
    bound = ("r* presses on a bound of the interval: the best value may lie outside it; "
             "widen the interval")
    assert explain([], [[1.0, 2.0]], "deg") == []
    assert explain(["pressing_on_bound"], [], "deg") == [bound]
    flat = explain(["flat"], [[30.0, 38.123456], [60.0, 70.0]], "deg")
    assert flat == [("E is flat around r*: every evaluated value in [30, 38.12] deg, [60, 70] deg "
                     "is as good to the tolerance")]
    assert explain(["pressing_on_bound", "flat"], [[0.0, 10.0]], "m") == [
        bound, "E is flat around r*: every evaluated value in [0, 10] m is as good to the tolerance"]
    assert explain(["flat"], [[0.0, 10.0]], "") == [  # no unit: no space for one
        "E is flat around r*: every evaluated value in [0, 10] is as good to the tolerance"]


RADAR, CAMERA = Radar.from_toml(), Camera.from_toml()
SUITE = Suite((RADAR, CAMERA))


@pytest.mark.parametrize("given, full", [("hfov_deg", "hfov_deg"), ("hfov", "hfov_deg"),
                                         ("radar.hfov_deg", "hfov_deg"), ("radar.range", "range_m"),
                                         ("tx_power", "tx_power_dbm"), ("noise_figure", "noise_figure_db")])
def test_a_radar_parameter_by_full_short_or_qualified_name(given, full):
    assert resolve_name(RADAR, given) == full


def test_suite_names_resolve_within_their_member():
    assert resolve_name(SUITE, "radar.hfov_deg") == "radar.hfov_deg"
    assert resolve_name(SUITE, "radar.hfov") == "radar.hfov_deg"
    assert resolve_name(SUITE, "camera.width") == "camera.width_px"
    # The first dot names the member, which resolves the rest: "radar.camera.hfov" asks the radar
    # for camera.hfov (refused below), "radar.radar.hfov" the radar for radar.hfov.
    assert resolve_name(SUITE, "radar.radar.hfov") == "radar.hfov_deg"


@pytest.mark.parametrize("sensor, name, message", [
    (RADAR, "fov", ("unknown radar parameter 'fov' (known: hfov (hfov_deg), vfov (vfov_deg), range (range_m), "
                    "tx_power (tx_power_dbm), noise_figure (noise_figure_db), yaw (yaw_deg), "
                    "mount_x (mount_x_m), mount_y (mount_y_m))")),
    (RADAR, "radar.hfov.deg", "unknown radar parameter 'hfov.deg' (known: "),
    (RADAR, "camera.hfov_deg", "parameter camera.hfov_deg names sensor 'camera', not in this problem (radar)"),
    (CAMERA, "camera.snr", "unknown camera parameter 'snr' (known: "),
    (SUITE, "hfov", "a suite's parameters are qualified by the sensor: give e.g. radar.hfov, camera.hfov"),
    (SUITE, "lidar.hfov", "parameter lidar.hfov names sensor 'lidar', not in the suite (radar, camera)"),
    (SUITE, "camera.snr", "unknown camera parameter 'snr' (known: "),
    (SUITE, "radar.camera.hfov", "parameter camera.hfov names sensor 'camera', not in this problem (radar)"),
])
def test_unknown_and_foreign_names_are_refused_with_the_known_ones(sensor, name, message):
    with pytest.raises(InputError) as info:
        resolve_name(sensor, name)
    assert str(info.value).startswith(message)


def test_bounds_are_resolved_checked_and_kept_as_floats():
    out = _resolve_params(RADAR, {"hfov": (30, 180), "radar.range_m": ("40", 90.5)})
    assert out == {"hfov_deg": (30.0, 180.0), "range_m": (40.0, 90.5)}
    assert all(type(v) is float for bounds in out.values() for v in bounds)
    assert list(out) == ["hfov_deg", "range_m"]
    # The domain's own edges: HFOV (0, 360] deg takes 360 and refuses 0.
    assert _resolve_params(RADAR, {"hfov": (359, 360)}) == {"hfov_deg": (359.0, 360.0)}


@pytest.mark.parametrize("params, message", [
    ({}, "params must name at least one parameter with its bounds, e.g. {'hfov_deg': (30, 180)}"),
    ([("hfov", (30, 180))], "params must name at least one parameter"),
    ({"hfov": (30, 60), "hfov_deg": (30, 90)}, "parameter hfov_deg is named twice"),
    ({"hfov": (30,)}, "bounds of hfov_deg must be two numbers (lo, hi), got (30,)"),
    ({"hfov": (30, 60, 90)}, "bounds of hfov_deg must be two numbers (lo, hi), got (30, 60, 90)"),
    ({"hfov": 30}, "bounds of hfov_deg must be two numbers (lo, hi), got 30"),
    ({"hfov": ("a", 60)}, "bounds of hfov_deg must be numbers, got 'a'"),
    ({"hfov": (30, math.inf)}, "bounds of hfov_deg must be finite numbers, got inf"),
    ({"hfov": (60, 60)}, "bounds of hfov_deg must have lo < hi, got 60 60"),
    ({"hfov": (60, 30)}, "bounds of hfov_deg must have lo < hi, got 60 30"),
    ({"hfov": (0, 30)}, "bounds 0 30 are outside the domain of hfov_deg: (0, 360] deg"),
    ({"hfov": (30, 361)}, "bounds 30 361 are outside the domain of hfov_deg: (0, 360] deg"),
])
def test_bad_bounds_are_one_line_each(params, message):
    with pytest.raises(InputError) as info:
        _resolve_params(RADAR, params)
    assert str(info.value).startswith(message) and "\n" not in str(info.value)


@pytest.mark.parametrize("value, ok", [(3, 3.0), ("2.5", 2.5), (-0.0, 0.0), (1e308, 1e308)])
def test_finite_takes_numbers(value, ok):
    assert _finite(value, "x") == ok and type(_finite(value, "x")) is float


@pytest.mark.parametrize("value, message", [(None, "cost_weight must be numbers, got None"),
                                            ("x", "cost_weight must be numbers, got 'x'"),
                                            (math.nan, "cost_weight must be finite numbers, got nan"),
                                            (-math.inf, "cost_weight must be finite numbers, got -inf")])
def test_finite_refuses_the_rest(value, message):
    with pytest.raises(InputError) as info:
        _finite(value, "cost_weight")
    assert str(info.value) == message
