"""The main job's flags made into `diffsense.Problem`s, in-process: which field each flag sets, the
sensors and parameter boxes they name, the temperature's rescaled continuation, and each refusal
naming its culprit (`python -m diffsense.optimise` prints it as its one `error:` line)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

import diffsense as ds
from diffsense.cli.optimise import _parser, pareto_lambdas, problems
from diffsense.study import load_suite

ROOT = Path(__file__).resolve().parents[1]
D4 = str(ROOT / "configs" / "suites" / "radar_camera_d4.toml")


def _problems(*argv: str) -> list:
    return problems(_parser().parse_args(list(argv)))


def _refused(culprit: str, *argv: str) -> None:
    with pytest.raises(ds.InputError, match=culprit):
        _problems(*argv)


def test_the_defaults_are_the_configs():
    (p,) = _problems()
    assert p == ds.Problem.from_toml()


def test_each_flag_sets_its_field(tmp_path):
    (p,) = _problems("--sensor", "camera", "--param", "hfov", "--interval", "20", "90", "--steps", "20, 45,90,",
                     "--scenarios", "sc02,sc03", "--variants", "3", "--seed", "7", "--fill", "zero",
                     "--objective", "tracked", "--miss-penalty", "25", "--predictor-dtype", "float32",
                     "--traffic-speed-offset-kmh", "-10", "--dense-check", "0.5",
                     "--rain-mm-h", "4", "--estimator", "mc", "--mc-samples", "5", "--cost-weight", "0.25",
                     "--draws", "12")
    assert p.keywords() == ds.Problem.from_toml().keywords() | {
        "sensor": "camera", "params": {"hfov_deg": (20.0, 90.0)}, "steps": (20.0, 45.0, 90.0),
        "scenarios": ("sc02", "sc03"), "variants": 3, "seed": 7, "fill": "zero", "objective": "tracked",
        "miss_penalty_m2": 25.0, "predictor_dtype": "float32", "traffic_speed_offset_kmh": -10.0, "dense_check": 0.5,
        "weather": {"rain_mm_h": 4.0, "fog_visibility_m": math.inf}, "cost_weight": 0.25,
        "estimator": ds.metrics.EstimatorConfig(kind="mc", samples=5, reference_draws=12)}
    (fog,) = _problems("--fog-visibility-m", "150")
    assert fog.traffic.weather == {"rain_mm_h": 0.0, "fog_visibility_m": 150.0}
    (tmp_path / "x.csv").touch()
    (paper,) = _problems("--profile", "paper", "--model", "weights.msgpack", "--scenes", f"highd:{tmp_path}/x.csv")
    assert (paper.sensing.profile, paper.prediction.predictor, paper.traffic.scenes) == (
        "paper", "weights.msgpack", f"highd:{tmp_path}/x.csv")
    laws = str(ROOT / "configs" / "sensors" / "laws" / "radar_swerling1.toml")
    (law,) = _problems("--sensor-config", laws)
    assert law.sensing.sensor_config == laws
    (axes,) = _problems("--r-star-axes")
    assert axes.solver.box.r_star_axes and not _problems()[0].solver.box.r_star_axes
    (fast,) = _problems("--predictor-dtype", "bfloat16")
    assert fast.prediction.predictor_dtype == "bfloat16"


def test_a_reference_needs_two_draws_for_its_standard_error():
    _refused("reference_draws must be >= 2", "--draws", "1")


def test_the_temperature_rescales_the_whole_continuation():
    (p,) = _problems("--tau", "0.5")
    assert p.solver.solve.tau_schedule == (2.0, 1.0, 0.5)
    (q,) = _problems("--tau", "3")
    assert q.solver.solve.tau_schedule == (12.0, 6.0, 3.0)
    assert q.solver.solve.max_evaluations == p.solver.solve.max_evaluations
    for bad in ("0", "-1", "inf", "nan"):
        _refused("--tau", "--tau", bad)


def test_which_sensors_and_parameters_the_flags_name():
    assert [p.sensor_kind for p in _problems("--sensor", "both")] == ["radar", "camera"]
    (suite,) = _problems("--sensor", "radar, camera,", "--param", "radar.hfov_deg=20:120",
                         "--param", "camera.hfov_deg=30:90")
    assert suite.sensing.sensor == ("radar", "camera")
    assert suite.params == {"radar.hfov_deg": (20.0, 120.0), "camera.hfov_deg": (30.0, 90.0)}
    (box,) = _problems("--param", " hfov_deg =40:100", "--param", "range_m=50:1.5e2")
    assert box.sensor_kind == "radar" and box.params == {"hfov_deg": (40.0, 100.0), "range_m": (50.0, 150.0)}
    (single,) = _problems("--param", "range")
    assert single.params == {"range_m": (30.0, 200.0)}  # the config's interval for the named parameter


@pytest.mark.parametrize("argv, culprit", [
    (("--sensor", "radar,camera"), "a suite needs its parameters as --param NAME=LO:HI"),
    *((("--param", text, "--param", "range=30:60"), "give NAME=LO:HI") for text in ("a", "a=1", "=1:2", " =1:2")),
    (("--param", "hfov=x:2", "--param", "range=30:60"), "'hfov=x:2': LO and HI must be numbers"),
    (("--param", "a=b=1:2", "--param", "c=0:1"), "LO and HI must be numbers"),
    (("--param", "hfov=30:60", "--param", " hfov=40:90"), "parameter hfov is named twice"),
    (("--param", "hfov=30:60", "--param", "range=30:60", "--interval", "1", "2"), "give no --interval"),
    (("--steps", "30,x"), "--steps must be comma-separated numbers"),
    (("--steps", ","), "--steps must be finite numbers"),
    (("--steps", "30,inf"), "--steps must be finite numbers"),
    (("--param", "hfov", "--interval", "30", "90", "--steps", "30,120"), r"steps \[30.0, 120.0\] leave the interval"),
    (("--variants", "0"), "variants must be an integer"),
    (("--param", "bogus", "--interval", "1", "2"), "unknown radar parameter 'bogus'"),
])
def test_a_bad_flag_is_refused_naming_its_culprit(argv, culprit):
    _refused(culprit, *argv)


def test_a_suite_file_replaces_sensor_and_param():
    (p,) = _problems("--suite", D4)
    assert p == ds.Problem.from_suite(D4)
    (q,) = _problems("--suite", D4, "--cost-weight", "0.125", "--variants", "1")
    assert q.question.cost_weight == 0.125 and q.traffic.variants == 1  # the flags over the file
    for flag in (("--sensor", "radar"), ("--param", "hfov"), ("--interval", "1", "2"), ("--steps", "1,2")):
        _refused(f"give no {flag[0]} with it", "--suite", D4, *flag)


def test_a_suite_files_members_constants_and_refusals(tmp_path):
    laws = ROOT / "configs" / "sensors" / "laws" / "radar_swerling1.toml"
    suite = tmp_path / "suite.toml"
    suite.write_text(f'sensors = ["radar", "camera"]\n[params]\n"radar.hfov_deg" = [20.0, 120.0]\n'
                     f'[sensor_config]\nradar = "{laws}"\n')
    (s,) = _problems("--suite", str(suite))
    assert s.sensing.sensor_config == load_suite(suite)["sensor_config"] == {"radar": str(laws)}
    suite.write_text('sensors = ["radar", "camera"]\n[params]\n"camera.zoom" = [1.0, 2.0]\n')
    _refused(f"^suite {suite}: unknown camera parameter 'zoom'", "--suite", str(suite))


def test_pareto_weights():
    def weights(*argv: str):
        args = _parser().parse_args(list(argv))
        return pareto_lambdas(args, problems(args))

    assert weights() is None
    assert weights("--pareto") == (0.0, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05)
    assert weights("--pareto", "0, 0.5,") == (0.0, 0.5)
    with pytest.raises(ds.InputError, match="--dense-check"):  # the other refusals: tests/test_cli_optimise.py
        weights("--pareto", "--dense-check", "1")


def test_a_config_fills_what_the_flags_leave(tmp_path):
    config = tmp_path / "mine.toml"
    config.write_text('[problem]\nvariants = 3\nsensor = "camera"\nparam = "width_px"\n'
                      "[solve]\ntau_schedule = [8.0, 4.0, 2.0]\n")
    (p,) = _problems("--config", str(config), "--tau", "0.5")
    assert (p.sensor_kind, p.params, p.traffic.variants) == ("camera", {"width_px": (640.0, 3840.0)}, 3)
    assert p.solver.solve.tau_schedule == (2.0, 1.0, 0.5)  # the config's continuation, ending at 0.5
    (r,) = _problems("--config", str(config), "--sensor", "radar", "--param", "range", "--interval", "50", "150")
    assert (r.sensor_kind, r.params, r.traffic.variants) == ("radar", {"range_m": (50.0, 150.0)}, 3)
    # A suite or a box names its own parameters: the config's camera-only one is not asked of them.
    (s,) = _problems("--config", str(config), "--suite", D4)
    assert s.sensing.sensor == ("radar", "camera") and s.traffic.variants == 3 and "radar.range_m" in s.params
    (b,) = _problems("--config", str(config), "--sensor", "radar", "--param", "hfov_deg=40:100",
                     "--param", "range_m=50:150")
    assert b.sensor_kind == "radar" and b.params == {"hfov_deg": (40.0, 100.0), "range_m": (50.0, 150.0)}
