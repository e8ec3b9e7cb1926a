"""result.json, key by key, from a `Result` built by hand (no program is compiled).

result.json is what a user's scripts read beside r*: its keys, in order, are the schema written
beside `diffsense.study.Result`, and each is pinned here to the value of the fields it comes from,
so a key that reads the wrong field, or is dropped, fails a test.
"""

from __future__ import annotations

import importlib.metadata
import math

import numpy as np
import pytest

import diffsense
from diffsense.solve import BoxResult, SolveResult, SweepPoint
from diffsense.study import Result

RESULT_KEYS = ("sensor", "params", "units", "param", "interval", "r_star", "E_soft_star", "E_hard_star", "reference",
               "judged", "ci_level", "ci_method", "E_ci", "r_star_ci", "comparisons", "sweep", "evaluations", "programs_run", "wall_s", "on_bound", "bracket", "tau_schedule", "notes",
               "objective", "breakdown_of", "E_pooled", "by_scenario", "by_horizon", "coverage", "tracked", "near_optimal", "flags", "domain",
               "sensitivity", "scenarios", "config", "versions")
PACKAGES = ("jax", "jaxlib", "flax", "optax", "optimistix", "numpy")  # beside python and diffsense

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


def test_json_ready_values_and_non_finite_numbers_as_null():
    out = _result(E_soft_star=np.float64(math.inf), domain={1: (np.float32(2.5), np.int32(3)), "a": np.array([[1.0, np.inf]]),
                                                           "b": [True, None, "x", -math.inf]}).to_json()
    assert out["E_soft_star"] is None and out["sweep"][1]["E_soft"] is None
    assert out["domain"] == {"1": [2.5, 3], "a": [[1.0, None]], "b": [True, None, "x", None]}
    assert type(out["domain"]["1"][0]) is float and type(out["domain"]["1"][1]) is int
    with pytest.raises(TypeError, match="object"):
        _result(domain={"a": [object()]}).to_json()


def test_versions_name_python_each_package_and_diffsense(monkeypatch):
    out = _result().to_json()["versions"]
    assert list(out) == ["python", *PACKAGES, "diffsense"] and out["diffsense"] == diffsense.__version__
    assert out["numpy"] == np.__version__
    real = importlib.metadata.version

    def version(name):
        if name == "optax":
            raise importlib.metadata.PackageNotFoundError(name)
        return real(name)

    monkeypatch.setattr(importlib.metadata, "version", version)
    out = _result().to_json()["versions"]
    assert out["optax"] == "not installed" and out["jax"] == real("jax")


def test_one_parameter_result_json_key_by_key():
    out = _result(breakdown=BREAKDOWN, tracked={"E_tracked": 3.0}, near_optimal={"tolerance_m": 0.02},
                  flags=("flat",), domain={"outside": []}, sensitivity={"rain_mm_h": {"hfov_deg": 0.1}},
                  reference={"answer_on": "E_hard"}, judged={"E_ref": 4.3, "E_ref_se": 0.1, "seed": 9, "variants": 2}
                  ).to_json()
    assert tuple(out) == RESULT_KEYS
    assert out["judged"] == {"E_ref": 4.3, "E_ref_se": 0.1, "seed": 9, "variants": 2}
    assert _result().to_json()["judged"] is None
    assert out["sensor"] == "radar" and out["params"] == {"hfov_deg": [30.0, 180.0]} and out["units"] == {"hfov_deg": "deg"}
    assert out["param"] == "hfov_deg" and out["interval"] == [30.0, 180.0] and out["r_star"] == {"hfov_deg": 42.0}
    assert (out["E_soft_star"], out["E_hard_star"]) == (4.2, 4.1) and out["reference"] == {"answer_on": "E_hard"}
    assert out["sweep"] == [{"r": 30.0, "E_hard": 5.0, "E_soft": 5.5, "E_ci": None},
                            {"r": 60.0, "E_hard": 4.0, "E_soft": None, "E_ci": None}]
    assert out["evaluations"] == {"objective": 7, "gradient": 3}
    assert out["programs_run"] == {"solve": {"soft": 3, "hard": 2}} and out["wall_s"] == {"compile": 1.5, "run": 2.5}
    assert out["on_bound"] is False and out["bracket"] == [30.0, 60.0] and out["tau_schedule"] == [4.0, 1.0]
    assert out["notes"] == ["a note"] and out["objective"] == "eq12"
    assert _result(solve=_solve(on_bound=True)).to_json()["on_bound"] is True
    assert out["by_scenario"] == {"sc01": 1.0} and out["by_horizon"] == {"t_s": [1.0]}
    assert (out["breakdown_of"], out["E_pooled"]) == ("E_hard", None)  # BREAKDOWN holds no pooled E
    drawn = _result(breakdown=BREAKDOWN | {"E_ref": 3.5}).to_json()  # a breakdown of E_ref's draws
    assert (drawn["breakdown_of"], drawn["E_pooled"]) == ("E_ref", 3.5)
    assert _result(breakdown=BREAKDOWN | {"E_hard": 4.1}).to_json()["E_pooled"] == 4.1
    assert out["coverage"] == {"at_instant": 0.5} and out["tracked"] == {"E_tracked": 3.0}
    assert out["near_optimal"] == {"tolerance_m": 0.02} and out["flags"] == ["flat"]
    assert out["domain"] == {"outside": []} and out["sensitivity"] == {"rain_mm_h": {"hfov_deg": 0.1}}
    assert out["scenarios"] == ["sc01", "sc02"] and out["config"] == {"variants": 2}
    assert list(out["versions"]) == ["python", *PACKAGES, "diffsense"]


def test_what_a_bare_result_writes_and_the_dense_check_added():
    out = _result(solve=_solve(on_bound=True)).to_json()
    assert "dense_check" not in out and out["on_bound"] is True and out["flags"] == []
    for key in ("by_scenario", "by_horizon", "coverage", "tracked", "near_optimal", "domain", "sensitivity", "reference"):
        assert out[key] is None, key
    out = _result(config={"objective": "tracked"}, dense_check={"step": 0.5}).to_json()
    assert out["objective"] == "tracked" and out["dense_check"] == {"step": 0.5}
    assert tuple(out) == (*RESULT_KEYS, "dense_check")


def test_sweep_entries_take_each_steps_by_scenario_and_coverage_only():
    steps = ({"by_scenario": {"sc01": 5.0}, "coverage": {"c": 1}, "extra": 9}, {"by_scenario": {}, "coverage": {}})
    out = _result(sweep_breakdown=steps).to_json()
    assert out["sweep"] == [{"r": 30.0, "E_hard": 5.0, "E_soft": 5.5, "E_ci": None, "by_scenario": {"sc01": 5.0},
                             "coverage": {"c": 1}},
                            {"r": 60.0, "E_hard": 4.0, "E_soft": None, "E_ci": None, "by_scenario": {}, "coverage": {}}]


def test_the_intervals_land_at_the_top_and_in_each_sweep_entry():
    method = {"method": "m", "resamples": 2000, "strata": "scenario", "seed": 0, "note": None}
    comparison = {"a": "60 deg", "b": "30 deg", "diff_m": 1.0, "ci": [0.5, 1.5], "ci_unpaired": [0.0, 2.0],
                  "paired": True, "verdict": "60 deg is worse than 30 deg by 1.00 m [0.50, 1.50]"}
    out = _result(intervals={"ci_level": 0.9, "ci_method": method, "E_ci": [3.9, 4.4],
                             "sweep_E_ci": [[4.8, 5.3], None], "r_star_ci": (30.0, 45.0),
                             "comparisons": [comparison]}).to_json()
    assert (out["ci_level"], out["ci_method"], out["E_ci"], out["comparisons"]) == (0.9, method, [3.9, 4.4], [comparison])
    assert out["r_star_ci"] == {out["param"]: [30.0, 45.0]}  # keyed by the parameter, as r_star is
    assert [p["E_ci"] for p in out["sweep"]] == [[4.8, 5.3], None]
    bare = _result().to_json()  # a job that computes none: null, an empty list and a note why
    assert bare["E_ci"] is None and bare["comparisons"] == [] and bare["ci_method"]["note"]
    assert bare["r_star_ci"] is None


def _box_result(**changes) -> Result:
    fields = {"params": {"hfov_deg": (30.0, 60.0), "range_m": (40.0, 90.0)}, "units": {"hfov_deg": "deg", "range_m": "m"},
              "r_star": {"hfov_deg": 30.0, "range_m": 70.0}, "solve": None, "box": _box(), "box_notes": ("box note",)}
    return _result(**fields | changes)


def test_box_result_json_key_by_key():
    out = _box_result(breakdown=BREAKDOWN, tracked={"E_tracked": 3.0}, domain={"outside": []},
                      sensitivity={"rain_mm_h": {}}, reference=None, config={"objective": "tracked"},
                      dense_check={"step": 1.0}, judged={"E_ref": 5.5, "E_ref_se": 0.2, "seed": 4, "variants": 1}
                      ).to_json()
    assert tuple(out) == (*RESULT_KEYS, "box")
    assert out["judged"] == {"E_ref": 5.5, "E_ref_se": 0.2, "seed": 4, "variants": 1}
    assert _box_result(box=_box(on_bound={"hfov_deg": "", "range_m": ""})).to_json()["on_bound"] is False
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
    assert out["scenarios"] == ["sc01", "sc02"] and out["reference"] is None
    assert out["box"] == {"J_star": 6.0, "cost": 2.0, "cost_weight": 0.5, "gradient": {"hfov_deg": 0.3, "range_m": -0.01},
                          "gradient_E": {"hfov_deg": 0.2, "range_m": -0.02},
                          "on_bound": {"hfov_deg": "lower", "range_m": ""}, "source": "start 1 tau 0.5",
                          "counts": {"soft": 11, "hard": 4}}
    bare = _box_result(box=_box(on_bound={"hfov_deg": "upper", "range_m": "lower"})).to_json()
    assert bare["flags"] == ["hfov_deg:on_upper_bound", "range_m:on_lower_bound"] and bare["objective"] == "eq12"
    assert bare["by_scenario"] is None and bare["by_horizon"] is None and bare["coverage"] is None
