"""An optimise config's every key reaches the `Problem` keyword arguments it names
(`diffsense.study._settings`), the command line's overrides win, and a missing interval is refused in
one line."""

from __future__ import annotations

import dataclasses

import pytest

from diffsense.study._settings import load_settings, problem_fields
from diffsense.runtime._errors import InputError
from diffsense.metrics import EstimatorConfig

EVERY_KEY = """
[problem]
sensor = "camera"
param = "width"
scenarios = ["sc02", "sc05"]
variants = 3
model = "weights.msgpack"
profile = "paper"
sensor_config = "mine.toml"
fill = "interp"
seed = 7
prediction_stride_frames = 6
background_vehicles = 2
float64 = false
predictor_dtype = "float64"
objective = "tracked"
miss_penalty_m2 = 64.0

[problem.estimator]
kind = "mc"
samples = 4

[solve]
max_evaluations = 11

[plots]
extra_curve_points = 5

[intervals.camera]
width_px = [800.0, 1600.0]
"""


def test_every_problem_key_reaches_its_keyword(tmp_path):
    path = tmp_path / "every.toml"
    path.write_text(EVERY_KEY)
    settings = load_settings(path)
    fields = problem_fields(settings)
    solve = fields.pop("solve")
    assert solve.max_evaluations == 11 and solve is settings.solve
    assert fields == {
        "sensor": "camera", "params": {"width_px": (800.0, 1600.0)}, "scenarios": ("sc02", "sc05"), "variants": 3,
        "seed": 7, "predictor": "weights.msgpack", "fill": "interp", "estimator": EstimatorConfig(kind="mc", samples=4),
        "profile": "paper", "sensor_config": "mine.toml", "prediction_stride_frames": 6, "background_vehicles": 2,
        "float64": False, "predictor_dtype": "float64", "objective": "tracked", "miss_penalty_m2": 64.0,
        "extra_curve_points": 5}


def test_the_shipped_defaults_and_their_empty_strings():
    fields = problem_fields(load_settings())
    assert fields["sensor"] == "radar" and fields["params"] == {"hfov_deg": (30.0, 180.0)}
    # "" in the file means "the profile's" / "none given": passed on as None, the model as "".
    assert fields["fill"] is None and fields["sensor_config"] is None and fields["predictor"] == ""
    assert (fields["variants"], fields["seed"], fields["extra_curve_points"]) == (8, 0, 0)


def test_overrides_win_and_a_missing_interval_is_refused():
    settings = load_settings()
    fields = problem_fields(settings, sensor="camera", param="baseline", interval=(0.1, 0.2))
    assert fields["sensor"] == "camera" and fields["params"] == {"baseline_m": (0.1, 0.2)}
    assert problem_fields(settings, param="range")["params"] == {"range_m": (30.0, 200.0)}
    assert problem_fields(settings, sensor="camera")["params"] == {"hfov_deg": (30.0, 180.0)}
    with pytest.raises(InputError) as info:
        problem_fields(settings, param="yaw")
    assert str(info.value) == "no interval for radar yaw_deg: give one (--interval LO HI, or [intervals.radar])"
    # A sensor with no [intervals] table at all (a registered one, say) is refused the same way.
    with pytest.raises(InputError, match=r"^no interval for radar hfov_deg: give one"):
        problem_fields(dataclasses.replace(settings, intervals={}))
