"""result.json, key by key, from a `Result` built by hand (no program is compiled).

result.json is what a user's scripts read beside r*: each key here is pinned to the value the
fields it comes from say, so a key that reads the wrong field, or is dropped, fails a test.
"""

from __future__ import annotations

import importlib.metadata
import math

import numpy as np
import pytest

import diffsense
from diffsense.study._result import _PACKAGES, RESULT_KEYS, Result, plain, versions
from diffsense.solve import SolveResult
from diffsense.solve._box import BoxResult
from diffsense.solve._steps import SweepPoint

SWEEP = (SweepPoint(30.0, 5.0, 5.5), SweepPoint(60.0, 4.0, math.nan))
BREAKDOWN = {"by_scenario": {"sc01": 1.0}, "by_horizon": {"t_s": [1.0]}, "coverage": {"at_instant": 0.5}}


def _solve(**changes) -> SolveResult:
    fields = {"r_star": 42.0, "E_soft_star": 4.2, "E_hard_star": 4.1, "sweep": SWEEP,
              "evaluations": {"objective": 7, "gradient": 3, "hard": 2}, "on_bound": False, "bracket": (30.0, 60.0),
              "tau_schedule": (4.0, 1.0), "levels": (), "notes": ("a note",), "interval": (30.0, 180.0),
              "wall_s": {"sweep": 1.0, "solve": 2.0}}
    return SolveResult(**fields | changes)


def _result(**changes) -> Result:
    fields = {"sensor": "radar", "params": {"hfov_deg": (30.0, 180.0)}, "units": {"hfov_deg": "deg"},
              "r_star": {"hfov_deg": 42.0}, "E_hard_star": 4.1, "E_soft_star": 4.2, "solve": _solve(),
              "programs_run": {"solve": {"soft": 3, "hard": 2}}, "wall_s": {"compile": 1.5, "run": 2.5},
              "scenarios": ("sc01", "sc02"), "config": {"variants": 2}}
    return Result(**fields | changes)


def _box(**changes) -> BoxResult:
    fields = {"names": ("hfov_deg", "range_m"), "bounds": {"hfov_deg": (30.0, 60.0), "range_m": (40.0, 90.0)},
              "x_star": {"hfov_deg": 30.0, "range_m": 70.0}, "J_star": 6.0, "E_hard": 5.0, "E_soft": 5.1, "cost": 2.0,
              "gradient": {"hfov_deg": 0.3, "range_m": -0.01}, "gradient_E": {"hfov_deg": 0.2, "range_m": -0.02},
              "on_bound": {"hfov_deg": "lower", "range_m": ""}, "source": "start 1 tau 0.5", "starts": (),
              "counts": {"soft": 11, "hard": 4}, "history": (), "tau_schedule": (2.0, 0.5), "cost_weight": 0.5}
    return BoxResult(**fields | changes)


def test_plain_makes_json_ready_values():
    value = {1: (np.float64(2.5), np.int32(3)), "a": np.array([[1.0, np.inf]]), "b": [True, None, "x", -math.inf]}
    out = plain(value)
    assert out == {"1": [2.5, 3], "a": [[1.0, None]], "b": [True, None, "x", None]}
    assert type(out["1"][0]) is float and type(out["1"][1]) is int and out["b"][0] is True
    assert plain(math.nan) is None and plain(0.0) == 0.0


def test_plain_refuses_what_json_cannot_hold():
    with pytest.raises(TypeError, match="^cannot write object to JSON$"):
        plain({"a": [object()]})


def test_versions_name_python_each_package_and_diffsense(monkeypatch):
    out = versions()
    assert list(out) == ["python", *_PACKAGES, "diffsense"] and out["diffsense"] == diffsense.__version__
    assert out["numpy"] == np.__version__
    real = importlib.metadata.version

    def version(name):
        if name == "optax":
            raise importlib.metadata.PackageNotFoundError(name)
        return real(name)

    monkeypatch.setattr(importlib.metadata, "version", version)
    assert versions()["optax"] == "not installed" and versions()["jax"] == real("jax")


def test_one_parameter_result_json_key_by_key():
    out = _result(breakdown=BREAKDOWN, tracked={"E_tracked": 3.0}, near_optimal={"tolerance_m": 0.02},
                  flags=("flat",), domain={"outside": []}, sensitivity={"rain_mm_h": {"hfov_deg": 0.1}},
                  reference={"answer_on": "E_hard"}).to_json()
    assert tuple(out) == RESULT_KEYS
    assert out["sensor"] == "radar" and out["params"] == {"hfov_deg": [30.0, 180.0]} and out["units"] == {"hfov_deg": "deg"}
    assert out["param"] == "hfov_deg" and out["interval"] == [30.0, 180.0] and out["r_star"] == {"hfov_deg": 42.0}
    assert (out["E_soft_star"], out["E_hard_star"]) == (4.2, 4.1) and out["reference"] == {"answer_on": "E_hard"}
    assert out["sweep"] == [{"r": 30.0, "E_hard": 5.0, "E_soft": 5.5}, {"r": 60.0, "E_hard": 4.0, "E_soft": None}]
    assert out["evaluations"] == {"objective": 7, "gradient": 3}
    assert out["programs_run"] == {"solve": {"soft": 3, "hard": 2}} and out["wall_s"] == {"compile": 1.5, "run": 2.5}
    assert out["on_bound"] is False and out["bracket"] == [30.0, 60.0] and out["tau_schedule"] == [4.0, 1.0]
    assert out["notes"] == ["a note"] and out["objective"] == "eq12"
    assert out["by_scenario"] == {"sc01": 1.0} and out["by_horizon"] == {"t_s": [1.0]}
    assert out["coverage"] == {"at_instant": 0.5} and out["tracked"] == {"E_tracked": 3.0}
    assert out["near_optimal"] == {"tolerance_m": 0.02} and out["flags"] == ["flat"]
    assert out["domain"] == {"outside": []} and out["sensitivity"] == {"rain_mm_h": {"hfov_deg": 0.1}}
    assert out["scenarios"] == ["sc01", "sc02"] and out["config"] == {"variants": 2}
    assert out["versions"] == versions()


def test_what_a_bare_result_writes():
    out = _result(solve=_solve(on_bound=True)).to_json()
    assert "dense_check" not in out and out["on_bound"] is True
    for key in ("by_scenario", "by_horizon", "coverage", "tracked", "near_optimal", "domain", "sensitivity", "reference"):
        assert out[key] is None, key
    assert out["flags"] == []


def test_the_objective_comes_from_the_config_and_the_dense_check_is_added():
    out = _result(config={"objective": "tracked"}, dense_check={"step": 0.5}).to_json()
    assert out["objective"] == "tracked" and out["dense_check"] == {"step": 0.5}
    assert tuple(out) == (*RESULT_KEYS, "dense_check")


def test_sweep_entries_take_each_steps_by_scenario_and_coverage_only():
    steps = ({"by_scenario": {"sc01": 5.0}, "coverage": {"c": 1}, "extra": 9}, {"by_scenario": {}, "coverage": {}})
    out = _result(sweep_breakdown=steps).to_json()
    assert out["sweep"] == [{"r": 30.0, "E_hard": 5.0, "E_soft": 5.5, "by_scenario": {"sc01": 5.0}, "coverage": {"c": 1}},
                            {"r": 60.0, "E_hard": 4.0, "E_soft": None, "by_scenario": {}, "coverage": {}}]


def test_the_one_parameter_properties():
    r = _result()
    assert r.sweep == SWEEP and r.evaluations == {"objective": 7, "gradient": 3, "hard": 2}
    assert r.notes == ("a note",) and r.on_bound is False and r.param == "hfov_deg"
    assert _result(solve=_solve(on_bound=True)).on_bound is True


def _box_result(**changes) -> Result:
    fields = {"params": {"hfov_deg": (30.0, 60.0), "range_m": (40.0, 90.0)}, "units": {"hfov_deg": "deg", "range_m": "m"},
              "r_star": {"hfov_deg": 30.0, "range_m": 70.0}, "solve": None, "box": _box(), "box_notes": ("box note",)}
    return _result(**fields | changes)


def test_the_box_properties():
    r = _box_result()
    assert r.sweep == () and r.param is None and r.notes == ("box note",)
    assert r.evaluations == {"objective": 4, "gradient": 11} and r.on_bound is True
    assert _box_result(box=_box(on_bound={"hfov_deg": "", "range_m": ""})).on_bound is False


def test_box_result_json_key_by_key():
    out = _box_result(breakdown=BREAKDOWN, tracked={"E_tracked": 3.0}, domain={"outside": []},
                      sensitivity={"rain_mm_h": {}}, reference=None, config={"objective": "tracked"},
                      dense_check={"step": 1.0}).to_json()
    assert tuple(out) == (*RESULT_KEYS, "box")
    assert out["params"] == {"hfov_deg": [30.0, 60.0], "range_m": [40.0, 90.0]} and out["units"]["range_m"] == "m"
    assert out["param"] is None and out["interval"] is None and out["sweep"] == [] and out["bracket"] is None
    assert out["r_star"] == {"hfov_deg": 30.0, "range_m": 70.0} and (out["E_soft_star"], out["E_hard_star"]) == (4.2, 4.1)
    assert out["evaluations"] == {"objective": 4, "gradient": 11} and out["on_bound"] is True
    assert out["tau_schedule"] == [2.0, 0.5] and out["notes"] == ["box note"] and out["objective"] == "tracked"
    assert out["flags"] == ["hfov_deg:on_lower_bound"] and out["near_optimal"] is None
    assert out["by_scenario"] == {"sc01": 1.0} and out["by_horizon"] == {"t_s": [1.0]}
    assert out["coverage"] == {"at_instant": 0.5} and out["tracked"] == {"E_tracked": 3.0}
    assert out["domain"] == {"outside": []} and out["sensitivity"] == {"rain_mm_h": {}}
    assert out["programs_run"] == {"solve": {"soft": 3, "hard": 2}} and out["wall_s"] == {"compile": 1.5, "run": 2.5}
    assert out["scenarios"] == ["sc01", "sc02"] and out["versions"] == versions() and out["reference"] is None
    assert out["box"] == {"J_star": 6.0, "cost": 2.0, "cost_weight": 0.5, "gradient": {"hfov_deg": 0.3, "range_m": -0.01},
                          "gradient_E": {"hfov_deg": 0.2, "range_m": -0.02},
                          "on_bound": {"hfov_deg": "lower", "range_m": ""}, "source": "start 1 tau 0.5",
                          "counts": {"soft": 11, "hard": 4}}


def test_a_box_without_a_breakdown_and_both_sides_on_bound():
    out = _box_result(box=_box(on_bound={"hfov_deg": "upper", "range_m": "lower"})).to_json()
    assert out["flags"] == ["hfov_deg:on_upper_bound", "range_m:on_lower_bound"]
    assert out["by_scenario"] is None and out["by_horizon"] is None and out["coverage"] is None
    assert out["objective"] == "eq12"
