"""What a `Problem` accepts, what it fills in, and every refusal by its whole message.

A Problem is the library's front door: each check here is a one-line `error:` a user reads,
and each default filled in decides what is simulated. Building a Problem compiles nothing.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import pytest

import diffsense as ds
from diffsense.runtime._errors import InputError
from diffsense.metrics import EstimatorConfig
from diffsense.sensors import Suite, make_sensor
from tests._toy_pipeline import ToySensor


def _refused(message: str, **fields):
    with pytest.raises(InputError) as caught:
        ds.Problem(**fields)
    assert str(caught.value) == message


def test_a_sensor_list_is_kept_as_a_tuple_and_makes_a_suite():
    p = ds.Problem(sensor=["radar", "camera"], params={"radar.hfov": (30, 60)})
    assert p.sensor == ("radar", "camera") and isinstance(p.make_sensor(), Suite)
    assert p.sensor_kind == "radar+camera" and p.params == {"radar.hfov_deg": (30.0, 60.0)}
    assert ds.Problem().sensor_kind == "radar" and ds.Problem(sensor="camera").sensor_kind == "camera"


def test_specs_name_each_free_parameter():
    specs = ds.Problem(params={"hfov": (30, 60), "range": (40, 90)}).specs()
    assert list(specs) == ["hfov_deg", "range_m"]
    assert (specs["hfov_deg"].unit, specs["range_m"].unit) == ("deg", "m")


@pytest.mark.parametrize("profile, fill", [("physical", "hold"), ("paper", "zero")])
def test_the_fill_defaults_to_the_profiles(profile, fill):
    assert ds.Problem(profile=profile).fill == fill
    assert ds.Problem(profile=profile, fill="interp").fill == "interp"


def test_an_unknown_fill_is_refused():
    _refused("unknown fill 'linear' (known: zero, hold, interp)", fill="linear")


def test_cost_weight_is_a_float_at_least_zero():
    p = ds.Problem(cost_weight=0)
    assert p.cost_weight == 0.0 and isinstance(p.cost_weight, float)
    assert ds.Problem(cost_weight="2.5").cost_weight == 2.5
    _refused("cost_weight must be >= 0, got -0.5", cost_weight=-0.5)
    _refused("cost_weight must be finite numbers, got inf", cost_weight=math.inf)


def test_scenarios_split_on_commas_and_lose_their_spaces():
    assert ds.Problem(scenarios=" sc01 , sc03").scenarios == ("sc01", "sc03")
    assert ds.Problem(scenarios=["sc02"]).scenarios == ("sc02",)


@pytest.mark.parametrize("scenarios", [[], "", "sc01,,sc03", ["sc01", " "]])
def test_an_empty_scenario_name_is_refused(scenarios):
    _refused("at least one scenario is needed (an empty name was given)", scenarios=scenarios)


def test_of_scenarios_named_twice_the_first_by_name_is_named():
    _refused("scenario named twice: sc02", scenarios=["sc03", "sc02", "sc03", "sc02"])
    _refused("scenario named twice: sc01", scenarios="sc01, sc01")


def test_an_estimator_name_becomes_its_config_and_a_config_is_kept():
    assert ds.Problem(estimator="mc").estimator == EstimatorConfig(kind="mc")
    config = EstimatorConfig(kind="mean-field", samples=3)
    assert ds.Problem(estimator=config).estimator is config


@pytest.mark.parametrize("name, lo, hi", [
    ("variants", 1, 100_000),
    ("seed", 0, 2**32 - 1),
    ("prediction_stride_frames", 1, 1000),
    ("background_vehicles", 0, 10_000),
    ("extra_curve_points", 0, 1000),
])
def test_each_integer_field_takes_its_whole_range_and_nothing_past_it(name, lo, hi):
    assert getattr(ds.Problem(**{name: lo}), name) == lo
    assert getattr(ds.Problem(**{name: hi}), name) == hi
    for bad in (lo - 1, hi + 1, float(lo), True):
        _refused(f"{name} must be an integer in [{lo}, {hi}], got {bad!r}", **{name: bad})


def test_weather_is_filled_in_and_checked_against_its_domain():
    assert ds.Problem().weather is None
    assert ds.Problem(weather={}).weather == {"rain_mm_h": 0.0, "fog_visibility_m": math.inf}
    w = ds.Problem(weather={"rain_mm_h": 500, "fog_visibility_m": "1"}).weather
    assert w == {"rain_mm_h": 500.0, "fog_visibility_m": 1.0} and isinstance(w["rain_mm_h"], float)
    assert ds.Problem(weather={"rain_mm_h": 0.0, "fog_visibility_m": math.inf}).weather["fog_visibility_m"] == math.inf


@pytest.mark.parametrize("weather, message", [
    ({"snow_mm_h": 1.0}, "unknown weather 'snow_mm_h' (known: rain_mm_h, fog_visibility_m)"),
    ({"rain_mm_h": "heavy"}, "weather rain_mm_h must be a number, got 'heavy'"),
    ({"rain_mm_h": None}, "weather rain_mm_h must be a number, got None"),
    ({"rain_mm_h": -0.1}, "weather rain_mm_h = -0.1 is outside [0, 500]"),
    ({"rain_mm_h": 500.5}, "weather rain_mm_h = 500.5 is outside [0, 500]"),
    ({"rain_mm_h": math.inf}, "weather rain_mm_h = inf is outside [0, 500]"),
    ({"rain_mm_h": math.nan}, "weather rain_mm_h = nan is outside [0, 500]"),
    ({"fog_visibility_m": 0.5}, "weather fog_visibility_m = 0.5 is outside [1, inf]"),
    ({"fog_visibility_m": math.nan}, "weather fog_visibility_m = nan is outside [1, inf]"),
])
def test_weather_outside_its_domain_is_refused(weather, message):
    _refused(message, weather=weather)


def test_the_paper_profile_takes_clear_weather_only():
    assert ds.Problem(profile="paper", weather={"rain_mm_h": 0}).weather == {"rain_mm_h": 0.0, "fog_visibility_m": math.inf}
    _refused("the paper profile is the paper's clear-weather design: use the physical profile for weather",
             profile="paper", weather={"fog_visibility_m": 500})


def test_the_predictor_dtype_and_its_refusals():
    for dtype in ("auto", "float32", "float64"):
        assert ds.Problem(predictor_dtype=dtype).predictor_dtype == dtype
    assert ds.Problem(predictor_dtype="float32", float64=False).predictor_dtype == "float32"
    _refused("predictor_dtype must be auto, float32 or float64, got 'bfloat16'", predictor_dtype="bfloat16")
    _refused("predictor_dtype float64 needs float64 = true (a float32 E cannot carry its digits)",
             predictor_dtype="float64", float64=False)


def test_recorded_scenes_are_named_by_kind_and_must_be_a_file(tmp_path):
    (tmp_path / "a:b").mkdir()
    csv = tmp_path / "a:b" / "01_tracks.csv"  # the kind ends at the first colon
    csv.write_text("")
    assert ds.Problem(scenes=f"highd:{csv}").scenes == f"highd:{csv}"
    assert ds.Problem(scenes=f"ngsim:{csv}").scenes == f"ngsim:{csv}"
    for bad in (f"waymo:{csv}", "highd", "highd:"):
        _refused(f"recorded scenes are named 'highd:PATH' or 'ngsim:PATH', got {bad!r}", scenes=bad)
    _refused(f"recorded scenes: {tmp_path} is not a file", scenes=f"ngsim:{tmp_path}")
    _refused("recorded scenes have the speeds they were recorded at: traffic_speed_offset_kmh "
             "applies to simulated scenarios only", scenes=f"highd:{csv}", traffic_speed_offset_kmh=-10)


def test_the_traffic_speed_offset_is_a_finite_float():
    p = ds.Problem(traffic_speed_offset_kmh=-20)
    assert p.traffic_speed_offset_kmh == -20.0 and isinstance(p.traffic_speed_offset_kmh, float)
    _refused("traffic_speed_offset_kmh must be finite numbers, got nan", traffic_speed_offset_kmh=math.nan)


def test_the_objective_and_its_miss_penalty():
    p = ds.Problem(objective="tracked", miss_penalty_m2=0)
    assert p.miss_penalty_m2 == 0.0 and type(p.miss_penalty_m2) is float
    _refused("unknown objective 'rmse' (known: eq12, tracked)", objective="rmse")
    _refused("miss_penalty_m2 must be >= 0, got -1", miss_penalty_m2=-1)
    _refused("miss_penalty_m2 must be numbers, got 'high'", miss_penalty_m2="high")


def test_steps_are_floats_for_one_parameter_only():
    p = ds.Problem(steps=[30, "45", 60.5])
    assert p.steps == (30.0, 45.0, 60.5) and all(isinstance(v, float) for v in p.steps)
    _refused("steps apply to one-parameter problems only", params={"hfov": (30, 60), "range": (40, 90)}, steps=[30])
    _refused("steps must be finite numbers, got inf", steps=[30, math.inf])


def test_the_dense_check_step_is_positive_and_makes_at_most_100000_points():
    assert ds.Problem(params={"hfov": (30, 130)}, dense_check=0.001).dense_check == 0.001  # exactly 100,000
    _refused("dense_check 0.00099 makes over 100,000 points on [30, 130]", params={"hfov": (30, 130)}, dense_check=0.00099)
    _refused("dense_check 0.000999995 makes over 100,000 points on [30, 130]", params={"hfov": (30, 130)},
             dense_check=0.000999995)  # 100,000.5 steps
    for bad in (0, -1.0, math.nan, math.inf):
        _refused(f"dense_check must be a positive step, got {bad}", dense_check=bad)
    _refused("dense_check applies to one-parameter problems only",
             params={"hfov": (30, 60), "range": (40, 90)}, dense_check=1.0)


def test_one_sensor_takes_the_profile_and_the_sensor_config(tmp_path):
    toml = tmp_path / "radar.toml"
    toml.write_text("snr_threshold_db = 10.0\n")
    assert ds.Problem(sensor_config=str(toml)).make_sensor().config.snr_threshold_db == 10.0
    paper = ds.Problem(profile="paper").make_sensor().config
    assert paper == make_sensor("radar", None, "paper").config and paper != make_sensor("radar").config


def test_sensor_configs_by_member_name(tmp_path):
    toml = tmp_path / "radar.toml"
    toml.write_text("snr_threshold_db = 10.0\n")
    p = ds.Problem(sensor=["radar", "camera"], params={"radar.hfov": (30, 60)}, sensor_config={"radar": str(toml)})
    radar, camera = p.make_sensor().members
    assert radar.config.snr_threshold_db == 10.0 and camera.kind == "camera"
    paper = ds.Problem(sensor=["radar", "camera"], params={"radar.hfov": (30, 60)}, sensor_config={"radar": str(toml)},
                       profile="paper")
    radar, camera = paper.make_sensor().members  # the member not named keeps its profile's constants
    assert radar.config.snr_threshold_db == 10.0 and camera.config == make_sensor("camera", None, "paper").config
    assert camera.config != make_sensor("camera").config
    obj = make_sensor("radar")
    toml.with_name("camera.toml").write_text("")
    assert ds.Problem(sensor=(obj, "camera"), params={"camera.hfov": (30, 60)},
                      sensor_config={"camera": str(toml.with_name("camera.toml"))}).make_sensor().members[0] is obj
    assert ds.Problem(sensor=("radar", "camera"), params={"radar.hfov": (30, 60)}).make_sensor().members[0].config.snr_threshold_db == 13.2


@pytest.mark.parametrize("fields, message", [
    ({"sensor": "radar", "sensor_config": {"radar": "x.toml"}},
     "a sensor_config by member name is for a suite (two or more sensors); give one sensor a path"),
    ({"sensor": ("radar",), "sensor_config": {"radar": "x.toml"}},
     "a sensor_config by member name is for a suite (two or more sensors); give one sensor a path"),
    ({"sensor": ("radar", "camera"), "sensor_config": {"lidar": "x.toml"}},
     "sensor_config names 'lidar', not a member of the suite (radar, camera)"),
    ({"sensor": (make_sensor("radar"), "camera"), "sensor_config": {"radar": "x.toml"}},
     "sensor_config for 'radar': that member is a Sensor object, which carries its own constants"),
    ({"sensor": ("radar", "camera"), "sensor_config": {"camera": 3}},
     "sensor_config for 'camera' must be a TOML path, got 3"),
])
def test_sensor_configs_by_member_name_refused(fields, message):
    _refused(message, params={"radar.hfov": (30, 60)}, **fields)


class _ArraySensor(ToySensor):
    """A user's sensor holding an array: unhashable, so never looked up in a dict."""

    gain: jax.Array


def test_a_sensor_object_holding_an_array_joins_a_suite_with_configs():
    sensor = _ArraySensor(gain=jnp.ones(2))
    problem = ds.Problem(sensor=(sensor, "camera"), params={"camera.hfov": (30, 60)},
                         sensor_config={"camera": "configs/sensors/laws/camera_confidence.toml"})
    toy, camera = problem.make_sensor().members
    assert toy is sensor and camera.config.detection.law == "confidence"


def test_a_sensor_object_under_another_profile_is_refused_with_or_without_configs(tmp_path):
    toml = tmp_path / "camera.toml"
    toml.write_text("")
    message = "a Sensor object carries its own constants: give no sensor config or profile with it"
    for configs in (None, {"camera": str(toml)}):
        _refused(message, sensor=(make_sensor("radar"), "camera"), params={"camera.hfov": (30, 60)},
                 profile="paper", sensor_config=configs)


def test_from_toml_keeps_the_files_values_under_overrides(tmp_path):
    path = tmp_path / "p.toml"
    path.write_text('[problem]\nvariants = 3\nseed = 7\n')
    p = ds.Problem.from_toml(path, seed=11)
    assert (p.variants, p.seed) == (3, 11)
