"""The printed tables, whole: what the main job prints beside r*, written out by hand from the
result dict each is given (columns, alignment, rounding, every word)."""

from __future__ import annotations

import math

import pytest

from diffsense.report._tables import (
    _cell,
    _r,
    box_table,
    breakdown_table,
    comparison_table,
    format_table,
    summary_table,
)


def test_cells_and_alignment():
    assert [_cell(v) for v in (None, True, False, 1.23456, 7, "x")] == ["-", "yes", "no", "1.2346", "7", "x"]
    text = format_table(["name", "value", ""], [["a", 1.5, "ok"], ["longer", None, ""]])
    assert text == ("name     value\n"
                    "------  ------  --\n"
                    "a       1.5000  ok\n"
                    "longer       -")


def _line(**changes):
    result = {
        "sensor": "radar", "param": "hfov_deg", "interval": [30.0, 180.0],
        "sweep": [{"r": 30.0, "E_hard": 5.0, "E_soft": 5.5}, {"r": 60.0, "E_hard": 4.0, "E_soft": None},
                  {"r": 90.0, "E_hard": None, "E_soft": 6.0}],
        "on_bound": False, "r_star": {"hfov_deg": 55.123456}, "E_hard_star": 3.9, "E_soft_star": 3.95,
        "reference": {"answer_on": "E_hard"}, "evaluations": {"objective": 7, "gradient": 3},
        "wall_s": {"compile": 1.26, "run": 2.04}, "notes": ["a note"], "near_optimal": {"intervals": [[50.0, 60.0]]},
        "sensitivity": {"rain_mm_h": {"hfov_deg": 0.12346}, "fog_visibility_m": {"hfov_deg": None}}, "flags": [],
    }
    return result | changes


def test_the_summary_of_a_threshold_law_run():
    assert summary_table(_line(), unit="deg").splitlines() == [
        "radar: hfov_deg [deg] over [30, 180]",
        "r          E_hard [m]  E_soft [m]",
        "---------  ----------  ----------  ---------",
        "step 30        5.0000      5.5000",
        "step 60        4.0000           -  best step",
        "step 90             -      6.0000",
        "r* 55.123      3.9000      3.9500   interior",
        "continuous solve: 7 objective + 3 gradient evaluations; wall 1.3 s compile + 2.0 s run",
        "note: a note",
        "dr*/drain_mm_h: hfov_deg +0.1235",
        "dr*/dfog_visibility_m: hfov_deg undefined",
    ]


def test_the_summary_judged_on_e_ref_on_a_bound_with_flags_and_a_scale():
    sweep = [{"r": math.pi / 6, "E_hard": 5.0, "E_soft": 5.5}, {"r": math.pi / 3, "E_hard": 4.0, "E_soft": None},
             {"r": math.pi / 2, "E_hard": None, "E_soft": 6.0}]  # radians, shown in degrees
    result = _line(on_bound=True, r_star=math.pi / 6, interval=[math.pi / 6, math.pi], notes=[], sweep=sweep,
                   sensitivity={"rain_mm_h": {"hfov_deg": -0.5}}, flags=["pressing_on_bound", "flat"],
                   reference={"answer_on": "E_ref", "E_ref_star": 4.25, "E_ref_star_se": 0.0125, "draws": 32,
                              "estimator": "auto"})
    assert summary_table(result, scale=180 / math.pi).splitlines() == [
        "radar: hfov_deg over [30, 180]",
        "r        E_ref [m]  E_soft [m]",
        "-------  ---------  ----------  ---------",
        "step 30     5.0000      5.5000",
        "step 60     4.0000           -  best step",
        "step 90          -      6.0000",
        "r* 30       4.2500      3.9500   on bound",
        "continuous solve: 7 objective + 3 gradient evaluations; wall 1.3 s compile + 2.0 s run",
        ("E_ref(r*) = 4.2500 +- 0.0125 m (standard error; 32 detection draws; estimator auto); "
         "E_hard(r*) = 3.9000 m with each detection at its median"),
        "dr*/drain_mm_h: hfov_deg -0.5 (r* is on a bound, held there for small changes)",
        "warning: r* presses on a bound of the interval: the best value may lie outside it; widen the interval",
        "warning: E is flat around r*: every evaluated value in [50, 60] is as good to the tolerance",
    ]


def test_r_is_shown_converted_to_five_digits_or_as_a_dash():
    assert (_r(None, 57.3), _r(0.5, 2.0), _r(123.456789, 1.0)) == ("-", "1", "123.46")


def test_a_summary_without_notes_or_flags_and_a_sensitivity_to_two_parameters():
    result = {k: v for k, v in _line().items() if k not in ("notes", "flags", "near_optimal")}
    result["sensitivity"] = {"rain_mm_h": {"hfov_deg": 0.25, "range_m": None}}
    assert summary_table(result).splitlines()[-1] == "dr*/drain_mm_h: hfov_deg +0.25, range_m undefined"


def test_the_best_step_is_the_first_of_equals():
    sweep = [{"r": 1.0, "E_hard": 2.0, "E_soft": 2.0}, {"r": 2.0, "E_hard": 2.0, "E_soft": 1.0}]
    rows = summary_table(_line(sweep=sweep, sensitivity=None, notes=[])).splitlines()
    assert rows[3].endswith("best step") and not rows[4].endswith("best step")


def _pair():
    radar = _line()
    camera = _line(sensor="camera", E_hard_star=3.5, E_soft_star=3.6, on_bound=True, r_star=30.0,
                   sweep=[{"r": 30.0, "E_hard": 3.5, "E_soft": 3.6}, {"r": 60.0, "E_hard": 4.5, "E_soft": 4.6},
                          {"r": 90.0, "E_hard": 6.25, "E_soft": 6.0}])
    return {"radar": radar, "camera": camera}


def test_the_comparison_of_two_sensors():
    assert comparison_table(_pair(), unit="deg").splitlines() == [
        "radar vs camera: hfov_deg [deg], E_RMSE [m] between GT-input and sensor-input predictions",
        "                 radar  camera",
        "--------------  ------  ------",
        "E_hard at 30    5.0000  3.5000",
        "E_hard at 60    4.0000  4.5000",
        "E_hard at 90         -  6.2500",
        "r*              55.123      30",
        "E_hard(r*) [m]  3.9000  3.5000",
        "E_soft(r*) [m]  3.9500  3.6000",
        "r* on bound         no     yes",
        "best: camera at r* = 30 (E_hard = 3.5000 m)",
    ]


def test_the_comparison_without_a_unit_names_the_first_sensors_parameter_and_the_lowest_e_wins():
    pair = _pair()
    pair["camera"] = pair["camera"] | {"param": "camera.hfov_deg", "E_hard_star": 4.5}
    lines = comparison_table(pair).splitlines()
    assert lines[0] == "radar vs camera: hfov_deg, E_RMSE [m] between GT-input and sensor-input predictions"
    assert lines[-1] == "best: radar at r* = 55.123 (E_hard = 3.9000 m)"
    assert comparison_table(pair, unit="deg").startswith("radar vs camera: hfov_deg [deg], ")


def test_the_comparison_needs_results_on_the_same_steps():
    with pytest.raises(ValueError, match="^no results to compare$"):
        comparison_table({})
    pair = _pair()
    pair["camera"]["sweep"] = pair["camera"]["sweep"][:2]
    with pytest.raises(ValueError, match="^sensor 'camera' was swept on other steps than 'radar'$"):
        comparison_table(pair)


def test_the_breakdown_by_scenario_and_coverage():
    cov = {"at_instant": 0.5, "in_window": 0.75, "throughout": 0.25,
           "parts": {"throughout": {"share": 0.25, "E_hard": 1.0}, "never": {"share": 0.125, "E_hard": None}}}
    result = {"E_hard_star": 3.9, "coverage": cov,
              "by_scenario": {"sc01": {"E_hard": 4.0, "coverage": {"at_instant": 0.4, "in_window": 0.6, "throughout": 0.2}}},
              "tracked": {"E_tracked": 2.5, "missed_share": 0.0625, "J_m2": 12.0}}
    assert breakdown_table(result).splitlines() == [
        "at r*   E_hard [m]  seen at t  in window  throughout",
        "------  ----------  ---------  ---------  ----------",
        "sc01        4.0000     0.4000     0.6000      0.2000",
        "pooled      3.9000     0.5000     0.7500      0.2500",
        "by coverage: throughout 25% of instants, E 1.0000 m, never 12% of instants, E - m",
        "tracked question: E over tracked instants 2.5000 m, missed share 6.2%, J 12.0000 m^2",
    ]
    assert breakdown_table({"E_hard_star": 1.0, "by_scenario": {}}) == ""
    assert breakdown_table(result | {"tracked": None}).splitlines()[-1].startswith("by coverage:")


def _box(**changes):
    result = {
        "sensor": "radar+camera", "r_star": {"radar.range_m": 30.0, "camera.width_px": 1920.5},
        "units": {"radar.range_m": "m", "camera.width_px": "px"}, "E_hard_star": 4.0, "E_soft_star": 4.125,
        "reference": None, "notes": ["radar.range_m is on its lower bound"],
        "box": {"cost_weight": 0.005, "gradient": {"radar.range_m": 0.01, "camera.width_px": -2e-05},
                "on_bound": {"radar.range_m": "lower", "camera.width_px": ""}, "cost": 120.0, "J_star": 4.6,
                "source": "start 2 tau 0.5", "counts": {"soft": 40, "hard": 9}},
    }
    return result | changes


def test_the_box_summary():
    assert box_table(_box()).splitlines() == [
        "radar+camera: 2 parameters, J = E + 0.005 x cost",
        "parameter               r*  unit  dJ/dr at r*",
        "---------------  ---------  ----  -----------  --------",
        "radar.range_m      30.0000     m       0.0100     lower",
        "camera.width_px  1920.5000    px      -0.0000  interior",
        ("E_hard(r*) 4.0000 m, E_soft 4.1250 m, cost 120.0000, J 4.6000 (start 2 tau 0.5); "
         "40 value-and-gradient + 9 hard evaluations"),
        "note: radar.range_m is on its lower bound",
    ]


def test_a_box_summary_without_notes_or_soft_evaluations():
    result = {k: v for k, v in _box().items() if k != "notes"}
    result["box"] = result["box"] | {"counts": {"hard": 2}}
    lines = box_table(result).splitlines()
    assert lines[-1].endswith("0 value-and-gradient + 2 hard evaluations") and len(lines) == 6


def test_the_box_summary_judged_on_e_ref():
    reference = {"answer_on": "E_ref", "E_ref_star": 4.5, "E_ref_star_se": 0.02, "draws": 16, "estimator": "mc"}
    box = _box()["box"] | {"counts": {"soft": 3}}
    lines = box_table(_box(reference=reference, notes=[], box=box)).splitlines()
    assert lines[-2].endswith("3 value-and-gradient + 0 reference evaluations")
    assert lines[-1] == ("J is judged on E_ref: E_ref(r*) 4.5000 +- 0.0200 m (standard error; 16 detection draws; "
                         "estimator mc); E_hard(r*) has each detection at its median")
