"""The printed tables, from result dicts written by hand: the numbers on each line (converted,
rounded: E to 4 decimals, r to 5 significant digits, shares to percent), which step is best,
whether r* is on a bound, the warnings and the sensitivities; the columns aligned."""

from __future__ import annotations

import math
import re

import pytest

from diffsense.report import box_table, breakdown_table, comparison_table, format_table, summary_table

# A number standing alone: not inside a name (sc01, m^2), its sign kept (-0.0000, +0.1235).
_NUMBER = re.compile(r"(?<![\w.^+-])[-+]?\d+(?:\.\d+)?(?![\w.])")


def numbers(text: str) -> list[list[float]]:
    """The numbers on each line of `text`."""
    return [[float(x) for x in _NUMBER.findall(line)] for line in text.splitlines()]


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


def test_format_table_aligns_its_columns_and_writes_none_as_a_dash():
    text = format_table(["name", "value", ""], [["a", 1.5, True], ["longer", None, False], ["b", 7, "x"]])
    lines = text.splitlines()
    assert lines[2:] == ["a       1.5000  yes", "longer       -   no", "b            7    x"]
    assert len({len(line) for line in lines[1:]}) == 1  # the rule as wide as the rows


def test_the_summary_of_a_one_parameter_run():
    text = summary_table(_line(), unit="deg")
    lines = text.splitlines()
    assert numbers(text) == [[30, 180], [], [], [30, 5.0, 5.5], [60, 4.0], [90, 6.0], [55.123, 3.9, 3.95],
                             [7, 3, 1.3, 2.0], [], [0.1235], []]
    assert [("best" in line) for line in lines[3:6]] == [False, True, False]  # the least E_hard
    assert "deg" in lines[0] and "interior" in lines[6] and "on bound" not in text
    assert "a note" in lines[8] and "undefined" in lines[10] and "warning" not in text


def test_the_summary_judged_on_e_ref_on_a_bound_with_flags_and_a_scale():
    sweep = [{"r": math.pi / 6, "E_hard": 5.0, "E_soft": 5.5}, {"r": math.pi / 3, "E_hard": 4.0, "E_soft": None}]
    result = _line(on_bound=True, r_star=math.pi / 6, interval=[math.pi / 6, math.pi], notes=[], sweep=sweep,
                   sensitivity={"rain_mm_h": {"hfov_deg": -0.5}}, flags=["pressing_on_bound", "flat"],
                   reference={"answer_on": "E_ref", "E_ref_star": 4.25, "E_ref_star_se": 0.0125, "draws": 32,
                              "estimator": "auto"})
    text = summary_table(result, scale=180 / math.pi)  # radians shown in degrees
    lines = text.splitlines()
    assert numbers(text)[:7] == [[30, 180], [], [], [30, 5.0, 5.5], [60, 4.0], [30, 4.25, 3.95],
                                 [7, 3, 1.3, 2.0]]
    assert "E_ref" in lines[1] and "on bound" in lines[5]
    assert numbers(lines[7])[0] == [4.25, 0.0125, 32, 3.9]  # E_ref(r*) +- its standard error; E_hard(r*)
    assert numbers(lines[8])[0] == [-0.5] and "bound" in lines[8]  # r* held on its bound
    assert len([line for line in lines if line.startswith("warning")]) == 2 and numbers(lines[-1])[0] == [50, 60]


def test_the_best_step_is_the_first_of_equals():
    sweep = [{"r": 1.0, "E_hard": 2.0, "E_soft": 2.0}, {"r": 2.0, "E_hard": 2.0, "E_soft": 1.0}]
    lines = summary_table(_line(sweep=sweep, sensitivity=None, notes=[])).splitlines()
    assert "best" in lines[3] and "best" not in lines[4]


def _pair():
    camera = _line(sensor="camera", E_hard_star=3.5, E_soft_star=3.6, on_bound=True, r_star=30.0,
                   sweep=[{"r": 30.0, "E_hard": 3.5, "E_soft": 3.6}, {"r": 60.0, "E_hard": 4.5, "E_soft": 4.6},
                          {"r": 90.0, "E_hard": 6.25, "E_soft": 6.0}])
    return {"radar": _line(), "camera": camera}


def test_the_comparison_of_two_sensors_names_the_lower_e():
    text = comparison_table(_pair(), unit="deg")
    lines = text.splitlines()
    assert numbers(text) == [[], [], [], [30, 5.0, 3.5], [60, 4.0, 4.5], [90, 6.25], [55.123, 30], [3.9, 3.5],
                             [3.95, 3.6], [], [30, 3.5]]
    assert lines[1].split() == ["radar", "camera"] and lines[9].split()[-2:] == ["no", "yes"]
    assert lines[-1].split()[1] == "camera"
    pair = _pair()
    pair["camera"] = pair["camera"] | {"E_hard_star": 4.5}
    assert comparison_table(pair).splitlines()[-1].split()[1] == "radar"


def test_the_comparison_needs_results_on_the_same_steps():
    with pytest.raises(ValueError):
        comparison_table({})
    pair = _pair()
    pair["camera"]["sweep"] = pair["camera"]["sweep"][:2]
    with pytest.raises(ValueError, match="'camera'"):
        comparison_table(pair)


def test_the_breakdown_by_scenario_and_coverage():
    cov = {"at_instant": 0.5, "in_window": 0.75, "throughout": 0.25,
           "parts": {"throughout": {"share": 0.25, "E_hard": 1.0}, "never": {"share": 0.125, "E_hard": None}}}
    result = {"E_hard_star": 3.9, "coverage": cov,
              "by_scenario": {"sc01": {"E_hard": 4.0, "coverage": {"at_instant": 0.4, "in_window": 0.6, "throughout": 0.2}}},
              "tracked": {"E_tracked": 2.5, "missed_share": 0.0625, "J_m2": 12.0}}
    text = breakdown_table(result)
    assert numbers(text) == [[], [], [4.0, 0.4, 0.6, 0.2], [3.9, 0.5, 0.75, 0.25], [25, 1.0, 12], [2.5, 6.2, 12.0]]
    assert re.findall(r"\d+(?:\.\d+)?%", text) == ["25%", "12%", "6.2%"]  # shares of instants
    assert text.splitlines()[2].startswith("sc01")
    assert breakdown_table({"E_hard_star": 1.0, "by_scenario": {}}) == ""
    assert len(breakdown_table(result | {"tracked": None}).splitlines()) == 5
    # with the parts' intervals: a column beside each scenario's E and the pooled one, and each
    # coverage part's after its E
    with_ci = result | {"E_ci": [3.5, 4.25], "by_scenario": {"sc01": result["by_scenario"]["sc01"] | {"E_ci": [3.0, 5.0]}},
                        "coverage": cov | {"parts": {"throughout": cov["parts"]["throughout"] | {"E_ci": [0.5, 1.5]},
                                                     "never": cov["parts"]["never"] | {"E_ci": None}}}}
    lines = breakdown_table(with_ci).splitlines()
    assert "90% CI" in lines[0] and "[3.00, 5.00]" in lines[2] and "[3.50, 4.25]" in lines[3]
    assert "E 1.0000 m [0.50, 1.50]" in lines[4] and lines[4].endswith("E - m")


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
    text = box_table(_box())
    lines = text.splitlines()
    assert numbers(text) == [[2, 0.005], [], [], [30.0, 0.01], [1920.5, -0.0], [4.0, 4.125, 120.0, 4.6, 2, 0.5, 40, 9],
                             []]
    assert [line.split()[0] for line in lines[3:5]] == ["radar.range_m", "camera.width_px"]
    assert "lower" in lines[3] and "interior" in lines[4] and "px" in lines[4]
    without = {k: v for k, v in _box().items() if k != "notes"}
    without["box"] = without["box"] | {"counts": {"hard": 2}}
    assert numbers(box_table(without))[-1][-2:] == [0, 2]  # no soft evaluations: 0


def test_the_box_summary_judged_on_e_ref():
    reference = {"answer_on": "E_ref", "E_ref_star": 4.5, "E_ref_star_se": 0.02, "draws": 16, "estimator": "mc"}
    box = _box()["box"] | {"counts": {"soft": 3}}
    text = box_table(_box(reference=reference, notes=[], box=box))
    assert numbers(text)[-2][-2:] == [3, 0] and "reference" in text.splitlines()[-2]
    assert numbers(text)[-1] == [4.5, 0.02, 16]
