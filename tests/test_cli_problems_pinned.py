"""The main job's flags made into `diffsense.Problem`s, pinned in-process: which field each flag
sets, the sensors and parameter boxes they name, the temperature's rescaled continuation, and
every refusal by its whole message (`python -m diffsense.optimise` prints it as its `error:`
line)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from diffsense.cli._problems import _number_list, _param_boxes, problems
from diffsense.cli._suite import pareto_lambdas, suite_fields
from diffsense.cli.optimise import _parser
from diffsense.runtime._errors import InputError

ROOT = Path(__file__).resolve().parents[1]


def _problems(*argv: str) -> list:
    return problems(_parser().parse_args(list(argv)))


def _refusal(*argv: str) -> str:
    with pytest.raises(InputError) as err:
        _problems(*argv)
    return str(err.value)


def test_the_defaults_are_the_configs():
    (p,) = _problems()
    assert (p.sensor, p.params, p.variants, p.seed, p.fill, p.objective) == (
        "radar", {"hfov_deg": (30.0, 180.0)}, 8, 0, "hold", "eq12")
    assert p.steps is None and p.dense_check is None and p.weather is None and p.cost_weight == 0.0
    assert p.solve.tau_schedule == (4.0, 2.0, 1.0) and p.estimator.kind == "auto" and p.estimator.samples == 8


def test_each_flag_sets_its_field(tmp_path):
    (p,) = _problems("--sensor", "camera", "--param", "hfov", "--interval", "20", "90", "--steps", "20, 45,90,",
                     "--scenarios", "sc02,sc03", "--variants", "3", "--seed", "7", "--fill", "zero",
                     "--objective", "tracked", "--miss-penalty", "25", "--predictor-dtype", "float32",
                     "--traffic-speed-offset-kmh", "-10", "--dense-check", "0.5",
                     "--rain-mm-h", "4", "--estimator", "mc", "--mc-samples", "5", "--cost-weight", "0.25")
    assert p.sensor == "camera" and p.params == {"hfov_deg": (20.0, 90.0)}
    assert p.steps == (20.0, 45.0, 90.0) and p.scenarios == ("sc02", "sc03")
    assert (p.variants, p.seed, p.fill, p.objective, p.miss_penalty_m2) == (3, 7, "zero", "tracked", 25.0)
    assert (p.predictor_dtype, p.traffic_speed_offset_kmh, p.dense_check) == ("float32", -10.0, 0.5)
    assert p.weather == {"rain_mm_h": 4.0, "fog_visibility_m": math.inf} and p.cost_weight == 0.25
    assert (p.estimator.kind, p.estimator.samples) == ("mc", 5)
    (fog,) = _problems("--fog-visibility-m", "150")
    assert fog.weather == {"rain_mm_h": 0.0, "fog_visibility_m": 150.0}
    (tmp_path / "x.csv").touch()
    (paper,) = _problems("--profile", "paper", "--model", "weights.msgpack", "--scenes", f"highd:{tmp_path}/x.csv")
    assert (paper.profile, paper.predictor, paper.scenes) == ("paper", "weights.msgpack", f"highd:{tmp_path}/x.csv")


def test_the_temperature_rescales_the_whole_continuation():
    (p,) = _problems("--tau", "0.5")
    assert p.solve.tau_schedule == (2.0, 1.0, 0.5)
    (q,) = _problems("--tau", "3")
    assert q.solve.tau_schedule == (12.0, 6.0, 3.0) and q.solve.max_evaluations == p.solve.max_evaluations
    for bad in ("0", "-1", "inf", "nan"):
        assert _refusal("--tau", bad) == f"--tau must be a positive number, got {float(bad)}"


def test_which_sensors_a_flag_names():
    assert [p.sensor for p in _problems("--sensor", "both")] == ["radar", "camera"]
    (suite,) = _problems("--sensor", "radar, camera,", "--param", "radar.hfov_deg=20:120",
                         "--param", "camera.hfov_deg=30:90")
    assert suite.sensor == ("radar", "camera")
    assert suite.params == {"radar.hfov_deg": (20.0, 120.0), "camera.hfov_deg": (30.0, 90.0)}
    assert _refusal("--sensor", "radar,camera") == (
        "a suite needs its parameters as --param NAME=LO:HI (e.g. radar.hfov_deg=20:120)")
    (box,) = _problems("--param", "hfov_deg=40:100", "--param", "range_m=50:150")
    assert box.sensor == "radar" and box.params == {"hfov_deg": (40.0, 100.0), "range_m": (50.0, 150.0)}


def test_parameter_boxes():
    assert _param_boxes(None) == {} and _param_boxes([]) == {} and _param_boxes(["hfov"]) == {}
    assert _param_boxes(["a=1:2"]) == {"a": (1.0, 2.0)}
    assert _param_boxes([" a =-1:2.5", "b=0:1e3"]) == {"a": (-1.0, 2.5), "b": (0.0, 1000.0)}
    for text in ("a", "a=1", "=1:2", " =1:2", "a:1=2"):
        with pytest.raises(InputError) as err:
            _param_boxes([text, "b=0:1"])
        assert str(err.value) == f"--param {text!r}: give NAME=LO:HI when naming several parameters"
    with pytest.raises(InputError) as err:
        _param_boxes(["a=x:2", "b=0:1"])
    assert str(err.value) == "--param 'a=x:2': LO and HI must be numbers"
    with pytest.raises(InputError) as err:
        _param_boxes(["a=0:1", " a=2:3"])
    assert str(err.value) == "parameter a is named twice"
    assert _refusal("--param", "a=0:1", "--param", "b=0:1", "--interval", "1", "2") == (
        "--param NAME=LO:HI carries its bounds: give no --interval with it")


def test_number_lists():
    assert _number_list("1, 2.5,,3,", "--steps") == (1.0, 2.5, 3.0)
    for text, message in (("1,x", "--steps must be comma-separated numbers, got '1,x'"),
                          (",", "--steps must be finite numbers, got ','"),
                          ("1,inf", "--steps must be finite numbers, got '1,inf'"),
                          ("nan", "--steps must be finite numbers, got 'nan'")):
        with pytest.raises(InputError) as err:
            _number_list(text, "--steps")
        assert str(err.value) == message


def test_steps_outside_the_interval_are_refused_before_any_computation():
    assert _refusal("--param", "hfov", "--interval", "30", "90", "--steps", "30,120") == (
        "steps [30.0, 120.0] leave the interval [30.0, 90.0]")


def test_a_suite_file_replaces_sensor_and_param(tmp_path):
    suite_path = ROOT / "configs" / "suites" / "radar_camera_d4.toml"
    args = _parser().parse_args(["--suite", str(suite_path)])
    fields = suite_fields(args)
    (p,) = problems(args)
    assert p.sensor == tuple(fields["sensor"]) and p.params == fields["params"]
    assert p.cost_weight == fields["cost_weight"]
    (q,) = _problems("--suite", str(suite_path), "--cost-weight", "0.125")
    assert q.cost_weight == 0.125  # the flag over the file
    for flag in (("--sensor", "radar"), ("--param", "hfov"), ("--interval", "1", "2"), ("--steps", "1,2")):
        assert _refusal("--suite", str(suite_path), *flag) == (
            f"--suite names the sensors and parameters: give no {flag[0]} with it")
    assert suite_fields(_parser().parse_args([])) is None


def test_pareto_weights():
    def weights(*argv: str):
        args = _parser().parse_args(list(argv))
        return pareto_lambdas(args, problems(args))

    assert weights() is None
    assert weights("--pareto") == (0.0, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05)
    assert weights("--pareto", "0, 0.5,") == (0.0, 0.5)
    for argv, message in ((("--pareto", "0,x"), "--pareto must be comma-separated numbers, got '0,x'"),
                          (("--pareto", "--sensor", "both"),
                           "--pareto traces one problem's front: give one sensor or a suite, not both"),
                          (("--pareto", "--sensitivity", "rain_mm_h"), "--pareto takes no --sensitivity or --dense-check"),
                          (("--pareto", "--dense-check", "1"), "--pareto takes no --sensitivity or --dense-check")):
        with pytest.raises(InputError) as err:
            weights(*argv)
        assert str(err.value) == message


def test_a_config_fills_what_the_flags_leave(tmp_path):
    config = tmp_path / "mine.toml"
    config.write_text('[problem]\nvariants = 3\nsensor = "camera"\nparam = "width_px"\n'
                      "[solve]\ntau_schedule = [8.0, 4.0, 2.0]\n")
    (p,) = _problems("--config", str(config), "--tau", "0.5")
    assert (p.sensor, p.params, p.variants) == ("camera", {"width_px": (640.0, 3840.0)}, 3)
    assert p.solve.tau_schedule == (2.0, 1.0, 0.5)  # the config's continuation, ending at 0.5
    (r,) = _problems("--config", str(config), "--sensor", "radar", "--param", "range", "--interval", "50", "150")
    assert (r.sensor, r.params, r.variants) == ("radar", {"range_m": (50.0, 150.0)}, 3)
    # A suite or a box names its own parameters: the config's camera-only one is not asked of them.
    suite_path = ROOT / "configs" / "suites" / "radar_camera_d4.toml"
    (s,) = _problems("--config", str(config), "--suite", str(suite_path))
    assert s.sensor == ("radar", "camera") and s.variants == 3 and "radar.range_m" in s.params
    (b,) = _problems("--config", str(config), "--sensor", "radar", "--param", "hfov_deg=40:100",
                     "--param", "range_m=50:150")
    assert b.sensor == "radar" and b.params == {"hfov_deg": (40.0, 100.0), "range_m": (50.0, 150.0)}
    (single,) = _problems("--param", "range")
    assert single.params == {"range_m": (30.0, 200.0)}  # the config's interval for the named parameter


def test_sensor_constants_from_a_flag_or_a_suite(tmp_path):
    laws = ROOT / "configs" / "sensors" / "laws" / "radar_swerling1.toml"
    (p,) = _problems("--sensor-config", str(laws))
    assert p.sensor_config == str(laws)
    suite = tmp_path / "suite.toml"
    suite.write_text(f'sensors = ["radar", "camera"]\n[params]\n"radar.hfov_deg" = [20.0, 120.0]\n'
                     f'[sensor_config]\nradar = "{laws}"\n')
    (s,) = _problems("--suite", str(suite))
    assert s.sensor_config == {"radar": str(laws)}


def test_a_suites_refusal_names_the_file(tmp_path):
    suite = tmp_path / "suite.toml"
    suite.write_text('sensors = ["radar", "camera"]\n[params]\n"camera.zoom" = [1.0, 2.0]\n')
    assert _refusal("--suite", str(suite)).startswith(f"suite {suite}: unknown camera parameter 'zoom' (known: ")
    assert _refusal("--steps", "30,x") == "--steps must be comma-separated numbers, got '30,x'"
    assert _refusal("--param", "a=b=1:2", "--param", "c=0:1") == "--param 'a=b=1:2': LO and HI must be numbers"
    assert _refusal("--variants", "0") == "variants must be an integer in [1, 100000], got 0"  # no suite named
