"""What `ds.Problem` accepts, what it fills in, what it refuses, and what its specs hold.

A Problem is the library's front door: each default decides what is simulated, and each refusal
is a one-line `error:` naming its culprit. Building a Problem compiles nothing.
"""

from __future__ import annotations

import inspect
import math

import jax
import jax.numpy as jnp
import pytest

import diffsense as ds
from diffsense.metrics import PAPER_SCENARIOS, EstimatorConfig
from diffsense.sensors import Suite, make_sensor
from diffsense.solve import BoxConfig, SolveConfig
from diffsense.study import (
    PredictionSpec,
    QuestionSpec,
    SensingSpec,
    SolverSpec,
    TrafficSpec,
)
from tests._toy_pipeline import ToySensor

DEFAULTS = {
    "sensor": "radar", "params": {"hfov_deg": (30.0, 180.0)}, "scenarios": PAPER_SCENARIOS, "scenes": None,
    "variants": 8, "seed": 0, "predictor": "", "profile": "physical", "sensor_config": None, "fill": "hold",
    "estimator": EstimatorConfig(kind="auto"), "prediction_stride_frames": 4, "background_vehicles": 0,
    "float64": True, "predictor_dtype": "auto", "weather": None, "traffic_speed_offset_kmh": 0.0,
    "objective": "eq12", "miss_penalty_m2": 100.0, "steps": None, "solve": SolveConfig(), "dense_check": None,
    "extra_curve_points": 0, "cost_weight": 0.0, "costs": None, "box": BoxConfig(), "window_s": 10.0,
    "crossing_at_s": None, "target_ci": None,
}
TWO = {"hfov": (30, 60), "range": (40, 90)}


def test_the_defaults():
    p = ds.Problem()
    assert p.keywords() == DEFAULTS and PAPER_SCENARIOS == ("sc01", "sc02", "sc03", "sc04", "sc05", "sc06")
    assert list(inspect.signature(ds.Problem).parameters) == list(DEFAULTS)  # every keyword, in order
    assert p.sensor_kind == "radar" and p.params == {"hfov_deg": (30.0, 180.0)} and p.seed == 0
    assert ds.Problem(**p.keywords()) == p


def test_each_keyword_lands_in_its_stages_spec():
    p = ds.Problem(scenarios=["sc02"], variants=3, prediction_stride_frames=6, background_vehicles=2,
                   weather={"rain_mm_h": 4}, traffic_speed_offset_kmh=-5, sensor="camera", params={"width": (640, 1280)},
                   profile="physical", predictor="w.msgpack", predictor_dtype="float32", float64=True, fill="interp",
                   objective="tracked", miss_penalty_m2=25, estimator="mc", cost_weight=0.5, costs="c.toml",
                   steps=[640, 1280], solve=SolveConfig(max_evaluations=9), dense_check=64.0, extra_curve_points=3,
                   box=BoxConfig(starts=1), seed=9)
    assert p.traffic == TrafficSpec(("sc02",), None, 3, 6, 2, {"rain_mm_h": 4.0, "fog_visibility_m": math.inf}, -5.0)
    assert p.sensing == SensingSpec("camera", {"width_px": (640.0, 1280.0)}, "physical", None)
    assert p.prediction == PredictionSpec("w.msgpack", "float32", True, "interp")
    assert p.question == QuestionSpec("tracked", 25.0, EstimatorConfig(kind="mc"), 0.5, "c.toml")
    assert p.solver == SolverSpec((640.0, 1280.0), SolveConfig(max_evaluations=9), 64.0, 3, BoxConfig(starts=1))
    assert p.seed == 9 and p.sensor_kind == "camera" and p.sensing.kind == "camera"


def test_from_specs_builds_the_same_problem_and_checks_they_agree():
    flat = ds.Problem(sensor="camera", variants=2, seed=4)
    assert ds.Problem.from_specs(sensing=SensingSpec(sensor="camera"), traffic=TrafficSpec(variants=2), seed=4) == flat
    assert ds.Problem.from_specs() == ds.Problem()
    with pytest.raises(ds.InputError, match="paper profile"):
        ds.Problem.from_specs(sensing=SensingSpec(profile="paper"), traffic=TrafficSpec(weather={"rain_mm_h": 5}))
    with pytest.raises(ds.InputError, match="steps"):
        ds.Problem.from_specs(sensing=SensingSpec(params=TWO), solver=SolverSpec(steps=(30, 60)))


def test_replace_changes_a_keyword_and_keeps_the_rest():
    p = ds.Problem(sensor="camera", params={"hfov": (30, 90)}, variants=3)
    q = p.replace(variants=5, seed=2)
    assert q.keywords() == p.keywords() | {"variants": 5, "seed": 2} and p.traffic.variants == 3
    assert p.replace(sensor="radar", params={"range": (40, 90)}).params == {"range_m": (40.0, 90.0)}
    assert p.replace(profile="paper", fill=None).prediction.fill == "zero"  # None: the new profile's
    assert p.replace(profile="paper").prediction.fill == "hold"  # a fill filled in is kept
    with pytest.raises(ds.InputError, match="variants"):
        p.replace(variants=0)
    with pytest.raises(TypeError, match="colour"):
        p.replace(colour="red")


def test_names_resolve_to_the_sensors_full_names():
    assert ds.Problem(params={"hfov": (30, 180), "radar.range_m": ("40", 90)}).params == {
        "hfov_deg": (30.0, 180.0), "range_m": (40.0, 90.0)}
    specs = ds.Problem(params=TWO).sensing.specs
    assert list(specs) == ["hfov_deg", "range_m"] and (specs["hfov_deg"].unit, specs["range_m"].unit) == ("deg", "m")
    suite = ds.Problem(sensor=["radar", "camera"], params={"radar.hfov": (20, 120), "camera.width": (640, 3840)})
    assert suite.params == {"radar.hfov_deg": (20.0, 120.0), "camera.width_px": (640.0, 3840.0)}
    assert suite.sensing.sensor == ("radar", "camera") and isinstance(suite.sensing.built, Suite)
    assert suite.sensor_kind == "radar+camera"


def test_values_are_held_in_one_form():
    assert ds.Problem(scenarios=" sc01 , sc03").traffic.scenarios == ("sc01", "sc03")
    assert ds.Problem(estimator="mc").question.estimator == EstimatorConfig(kind="mc")
    config = EstimatorConfig(kind="mean-field", samples=3)
    assert ds.Problem(estimator=config).question.estimator == config
    for p, value in ((ds.Problem(cost_weight="2.5").question.cost_weight, 2.5),
                     (ds.Problem(miss_penalty_m2=0).question.miss_penalty_m2, 0.0),
                     (ds.Problem(traffic_speed_offset_kmh=-20).traffic.traffic_speed_offset_kmh, -20.0)):
        assert p == value and type(p) is float
    assert ds.Problem(steps=[30, "45", 60.5]).solver.steps == (30.0, 45.0, 60.5)
    assert ds.Problem(weather={}).traffic.weather == {"rain_mm_h": 0.0, "fog_visibility_m": math.inf}
    assert ds.Problem(weather={"fog_visibility_m": "1"}).traffic.weather == {"rain_mm_h": 0.0, "fog_visibility_m": 1.0}
    assert ds.Problem(profile="paper", weather={"rain_mm_h": 0}).traffic.weather["rain_mm_h"] == 0.0  # clear: fine
    assert ds.Problem(params={"hfov": (30, 130)}, dense_check=0.001).solver.dense_check == 0.001  # 100,000 points
    assert [ds.Problem(profile=p).prediction.fill for p in ("physical", "paper")] == ["hold", "zero"]  # the profile's
    assert ds.Problem(profile="paper", fill="interp").prediction.fill == "interp"


@pytest.mark.parametrize("name, lo, hi", [("variants", 1, 100_000), ("seed", 0, 2**32 - 1),
                                          ("prediction_stride_frames", 1, 1000), ("background_vehicles", 0, 10_000),
                                          ("extra_curve_points", 0, 1000)])
def test_each_integer_takes_its_whole_range_and_nothing_past_it(name, lo, hi):
    assert ds.Problem(**{name: lo}).keywords()[name] == lo and ds.Problem(**{name: hi}).keywords()[name] == hi
    for bad in (lo - 1, hi + 1, float(lo), True):
        with pytest.raises(ds.InputError, match=f"^{name} must be an integer in \\[{lo}, {hi}\\]"):
            ds.Problem(**{name: bad})


def _csv(tmp_path):
    (tmp_path / "a:b").mkdir()
    csv = tmp_path / "a:b" / "01_tracks.csv"  # the kind ends at the first colon
    csv.touch()
    return csv


def test_recorded_scenes_are_named_by_kind_and_must_be_a_file(tmp_path):
    csv = _csv(tmp_path)
    assert ds.Problem(scenes=f"highd:{csv}").traffic.scenes == f"highd:{csv}"
    assert ds.Problem(scenes=f"ngsim:{csv}").traffic.scenes == f"ngsim:{csv}"
    for bad in (f"waymo:{csv}", "highd", "highd:"):
        with pytest.raises(ds.InputError, match="'highd:PATH' or 'ngsim:PATH'"):
            ds.Problem(scenes=bad)
    for fields, culprit in (({"scenes": f"ngsim:{tmp_path}"}, "is not a file"),
                            ({"scenes": f"highd:{csv}", "traffic_speed_offset_kmh": -10}, "traffic_speed_offset_kmh")):
        with pytest.raises(ds.InputError, match=culprit):
            ds.Problem(**fields)


@pytest.mark.parametrize("fields, culprit", [
    ({"sensor": "lidar"}, "unknown sensor 'lidar'"),
    ({"params": {}}, "params must name at least one parameter"),
    ({"params": [("hfov", (30, 180))]}, "params must name at least one parameter"),
    ({"params": {"bogus": (1, 2)}}, "unknown radar parameter 'bogus'"),
    ({"params": {"camera.hfov_deg": (30, 60)}}, "camera.hfov_deg names sensor 'camera'"),
    ({"params": {"hfov": (30, 60), "hfov_deg": (30, 90)}}, "hfov_deg is named twice"),
    ({"params": {"hfov": (30,)}}, "bounds of hfov_deg must be two numbers"),
    ({"params": {"hfov": (30, 60, 90)}}, "bounds of hfov_deg must be two numbers"),
    ({"params": {"hfov": 30}}, "bounds of hfov_deg must be two numbers"),
    ({"params": {"hfov": ("a", 60)}}, "bounds of hfov_deg"),
    ({"params": {"hfov": (30, math.inf)}}, "bounds of hfov_deg"),
    ({"params": {"hfov": (60, 60)}}, "bounds of hfov_deg must have lo < hi"),
    ({"params": {"hfov": (0, 30)}}, "outside the domain of hfov_deg"),
    ({"params": {"hfov": (30, 361)}}, r"outside the domain of hfov_deg: \(0, 360\] deg"),
    ({"params": {"hfov": (60, 30)}}, "bounds of hfov_deg must have lo < hi"),
    ({"sensor": ["radar", "camera"], "params": {"hfov_deg": (20, 120)}}, "qualified by the sensor"),
    ({"sensor": ["radar", "camera"], "params": {"lidar.hfov_deg": (20, 120)}}, "'lidar', not in the suite"),
    ({"scenarios": []}, "at least one scenario"),
    ({"scenarios": ""}, "at least one scenario"),
    ({"scenarios": "sc01,,sc03"}, "at least one scenario"),
    ({"scenarios": ["sc01", " "]}, "at least one scenario"),
    ({"scenarios": ["sc03", "sc02", "sc03", "sc02"]}, "scenario named twice: sc02"),
    ({"weather": {"snow_mm_h": 1.0}}, "unknown weather 'snow_mm_h'"),
    ({"weather": {"rain_mm_h": "heavy"}}, "weather rain_mm_h must be a number"),
    ({"weather": {"rain_mm_h": None}}, "weather rain_mm_h must be a number"),
    ({"weather": {"rain_mm_h": -0.1}}, r"weather rain_mm_h = -0.1 is outside \[0, 500\]"),
    ({"weather": {"rain_mm_h": 500.5}}, "weather rain_mm_h = 500.5 is outside"),
    ({"weather": {"rain_mm_h": math.inf}}, "weather rain_mm_h = inf is outside"),
    ({"weather": {"rain_mm_h": math.nan}}, "weather rain_mm_h = nan is outside"),
    ({"weather": {"fog_visibility_m": 0.5}}, r"weather fog_visibility_m = 0.5 is outside \[1, inf\]"),
    ({"weather": {"fog_visibility_m": math.nan}}, "weather fog_visibility_m = nan is outside"),
    ({"profile": "paper", "weather": {"fog_visibility_m": 500}}, "paper profile"),
    ({"traffic_speed_offset_kmh": math.nan}, "traffic_speed_offset_kmh"),
    ({"predictor_dtype": "float16"}, "predictor_dtype must be auto, .*got 'float16'"),
    ({"predictor_dtype": "float64", "float64": False}, "predictor_dtype float64 needs float64"),
    ({"fill": "linear"}, "unknown fill 'linear'"),
    ({"estimator": "bogus"}, "unknown estimator 'bogus'"),
    ({"objective": "rmse"}, "unknown objective 'rmse'"),
    ({"miss_penalty_m2": -1}, "miss_penalty_m2 must be >= 0"),
    ({"miss_penalty_m2": "high"}, "miss_penalty_m2"),
    ({"cost_weight": -0.5}, "cost_weight must be >= 0"),
    ({"cost_weight": math.inf}, "cost_weight"),
    ({"steps": [30, math.inf]}, "steps"),
    ({"params": TWO, "steps": [30]}, "steps apply to one-parameter problems only"),
    ({"dense_check": 0}, "dense_check must be a positive step"),
    ({"dense_check": -1.0}, "dense_check must be a positive step"),
    ({"dense_check": math.nan}, "dense_check must be a positive step"),
    ({"dense_check": math.inf}, "dense_check must be a positive step"),
    ({"params": TWO, "dense_check": 1.0}, "dense_check applies to one-parameter problems only"),
    ({"params": {"hfov": (30, 130)}, "dense_check": 0.00099}, r"dense_check 0.00099 makes over 100,000 points"),
    ({"params": {"hfov": (30, 130)}, "dense_check": 0.000999995}, "makes over 100,000 points"),  # 100,000.5 steps
])
def test_a_refusal_names_its_culprit(fields, culprit):
    with pytest.raises(ds.InputError, match=culprit) as caught:
        ds.Problem(**fields)
    assert "\n" not in str(caught.value)


def test_one_sensor_takes_the_profile_and_the_sensor_config(tmp_path):
    toml = tmp_path / "radar.toml"
    toml.write_text("snr_threshold_db = 10.0\n")
    assert ds.Problem(sensor_config=str(toml)).sensing.built.config.snr_threshold_db == 10.0
    paper = ds.Problem(profile="paper").sensing.built.config
    assert paper == make_sensor("radar", None, "paper").config and paper != make_sensor("radar").config


def test_sensor_configs_by_member_name(tmp_path):
    toml = tmp_path / "radar.toml"
    toml.write_text("snr_threshold_db = 10.0\n")
    suite = {"sensor": ["radar", "camera"], "params": {"radar.hfov": (30, 60)}, "sensor_config": {"radar": str(toml)}}
    radar, camera = ds.Problem(**suite).sensing.built.members
    assert radar.config.snr_threshold_db == 10.0 and camera.kind == "camera"
    radar, camera = ds.Problem(**suite, profile="paper").sensing.built.members  # the other keeps its profile's
    assert radar.config.snr_threshold_db == 10.0 and camera.config == make_sensor("camera", None, "paper").config
    assert camera.config != make_sensor("camera").config
    assert ds.Problem(sensor=("radar", "camera"), params={"radar.hfov": (30, 60)}).sensing.built.members[0].config == \
        make_sensor("radar").config


class _ArraySensor(ToySensor):
    """A user's sensor holding an array: unhashable, so never looked up in a dict."""

    gain: jax.Array


def test_a_sensor_object_is_used_as_given_in_a_suite_with_configs():
    sensor = _ArraySensor(gain=jnp.ones(2))
    problem = ds.Problem(sensor=(sensor, "camera"), params={"camera.hfov": (30, 60)},
                         sensor_config={"camera": "configs/sensors/laws/camera_confidence.toml"})
    toy, camera = problem.sensing.built.members
    assert toy is sensor and camera.config.detection.law == "confidence"


@pytest.mark.parametrize("fields, culprit", [
    ({"sensor": "radar", "sensor_config": {"radar": "x.toml"}}, "is for a suite"),
    ({"sensor": ("radar",), "sensor_config": {"radar": "x.toml"}}, "is for a suite"),
    ({"sensor": ("radar", "camera"), "sensor_config": {"lidar": "x.toml"}}, "sensor_config names 'lidar'"),
    ({"sensor": (make_sensor("radar"), "camera"), "sensor_config": {"radar": "x.toml"}}, "for 'radar'"),
    ({"sensor": ("radar", "camera"), "sensor_config": {"camera": 3}}, "for 'camera' must be a TOML path"),
    ({"sensor": (make_sensor("radar"), "camera"), "profile": "paper"}, "a Sensor object carries its own constants"),
    ({"sensor": (make_sensor("radar"), "camera"), "profile": "paper", "sensor_config": {"camera": "c.toml"}},
     "a Sensor object carries its own constants"),
])
def test_sensor_configs_that_cannot_apply_are_refused(fields, culprit):
    with pytest.raises(ds.InputError, match=culprit):
        ds.Problem(params={"camera.hfov": (30, 60)} if "profile" in fields else {"radar.hfov": (30, 60)}, **fields)


EVERY_KEY = ('problem = { sensor = "camera", param = "width", scenarios = ["sc02", "sc05"], variants = 3, '
             'model = "weights.msgpack", profile = "paper", fill = "interp", seed = 7, prediction_stride_frames = 6, '
             'background_vehicles = 2, float64 = false, predictor_dtype = "float32", objective = "tracked", '
             'miss_penalty_m2 = 64.0, estimator = { kind = "mc", samples = 4 } }\n'
             "solve = { max_evaluations = 11 }\nplots = { extra_curve_points = 5 }\n"
             "intervals = { camera = { width_px = [800.0, 1600.0] } }\n")


def test_from_toml_every_key_reaches_its_keyword(tmp_path):
    path = tmp_path / "every.toml"
    path.write_text(EVERY_KEY)
    p = ds.Problem.from_toml(path)
    assert p.keywords() == DEFAULTS | {
        "sensor": "camera", "params": {"width_px": (800.0, 1600.0)}, "scenarios": ("sc02", "sc05"), "variants": 3,
        "seed": 7, "predictor": "weights.msgpack", "fill": "interp", "estimator": EstimatorConfig(kind="mc", samples=4),
        "profile": "paper", "prediction_stride_frames": 6, "background_vehicles": 2, "float64": False,
        "predictor_dtype": "float32", "objective": "tracked", "miss_penalty_m2": 64.0,
        "solve": SolveConfig(max_evaluations=11), "extra_curve_points": 5}
    laws = "configs/sensors/laws/radar_swerling1.toml"
    path.write_text(f'[problem]\nsensor_config = "{laws}"\n')
    assert ds.Problem.from_toml(path).sensing.sensor_config == laws


def test_from_toml_keeps_the_defaults_the_file_leaves_and_the_overrides_win(tmp_path):
    assert ds.Problem.from_toml() == ds.Problem()  # the shipped file: "" means the profile's, or none
    path = tmp_path / "p.toml"
    path.write_text('[problem]\nvariants = 3\nseed = 7\nsensor = "camera"\nparam = "baseline"\n')
    p = ds.Problem.from_toml(path, seed=11)
    assert (p.traffic.variants, p.seed, p.params) == (3, 11, {"baseline_m": (0.05, 0.5)})  # its [intervals] entry
    path.write_text('[problem]\nparam = "yaw"\n')
    with pytest.raises(ds.InputError, match=r"no interval for radar yaw_deg.*\[intervals.radar\]"):
        ds.Problem.from_toml(path)
    path.write_text("[problem]\nvariants = 'many'\n")
    with pytest.raises(ds.InputError, match="problem.variants"):
        ds.Problem.from_toml(path)
