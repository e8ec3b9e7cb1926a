"""The main job's command line in-process, with the library's solve and the report replaced by
recorders: what it asks of `diffsense.optimise` per sensor, where each sensor's files go, the
comparison it publishes and prints, its progress lines, the multi-process worker's silence, and
every refusal before any computation by its whole message."""

from __future__ import annotations

import math
import shutil
import threading
from pathlib import Path
from typing import ClassVar

import pytest

import diffsense as ds
import diffsense.predictors
from diffsense import _distributed, _optimise, cli, report
from diffsense.cli import optimise
from diffsense.runtime._errors import InputError


class _Progress:
    made: ClassVar[list] = []  # every display made, in order

    def __init__(self, quiet):
        self.quiet, self.lines, self.evaluation = quiet, [], "the display's hook"
        _Progress.made.append(self)

    def __call__(self, message):
        self.lines.append(message)


@pytest.fixture
def recorded(monkeypatch):
    """Replaces the solve, the predictor's load, the report's writer and tables, and JAX's set-up."""
    log = {"solved": [], "written": [], "setup": []}

    def solve(problem, **kw):
        log["solved"].append((problem.sensor_kind, dict(problem.params), kw))
        return f"result {problem.sensor_kind}"

    def write_run(result, folder):
        log["written"].append((result, Path(folder).name))
        Path(folder).mkdir(parents=True, exist_ok=True)
        (Path(folder) / "result.json").write_text(result)
        kind = result.split()[1]
        return {"param": "hfov_deg", "units": {"hfov_deg": "deg"}, "sensor": kind}

    monkeypatch.setattr(ds, "optimise", solve)
    monkeypatch.setattr(diffsense.predictors, "load_predictor", lambda model: f"predictor {model!r}")
    monkeypatch.setattr(report, "write_run", write_run)
    monkeypatch.setattr(report, "summary_table", lambda content, unit: f"summary {content['sensor']} [{unit}]")
    monkeypatch.setattr(report, "box_table", lambda content: f"box {content['sensor']}")
    monkeypatch.setattr(report, "breakdown_table", lambda content: f"breakdown {content['sensor']}")
    monkeypatch.setattr(report, "comparison_table", lambda results, unit: f"compared {' '.join(results)} [{unit}]")
    monkeypatch.setattr(cli, "setup_jax", lambda float64: log["setup"].append(float64))
    monkeypatch.setattr(optimise, "Progress", _Progress)
    _Progress.made = []
    return log


def test_both_sensors_solve_one_after_the_other_and_publish_a_comparison(tmp_path, recorded, capsys):
    out = tmp_path / "out"
    assert optimise.main(["--sensor", "both", "--param", "hfov", "--interval", "30", "180", "--out", str(out)]) == 0
    assert [(kind, params) for kind, params, _ in recorded["solved"]] == [
        ("radar", {"hfov_deg": (30.0, 180.0)}), ("camera", {"hfov_deg": (30.0, 180.0)})]
    (progress,) = _Progress.made
    for _, _, kw in recorded["solved"]:
        assert kw == {"predictor": "predictor None", "progress": progress, "on_evaluation": "the display's hook",
                      "sensitivity": ()}
    assert recorded["written"] == [("result radar", "radar"), ("result camera", "camera")]
    assert recorded["setup"] == [True]
    assert sorted(p.name for p in out.iterdir()) == ["camera", "comparison.txt", "manifest.json", "radar"]
    assert (out / "comparison.txt").read_text() == "compared radar camera [deg]\n"
    assert (out / "radar" / "result.json").read_text() == "result radar"
    assert progress.lines == ["loaded the predictor (shipped weights)",
                              (f"wrote {out}/: result.json, objective.png, rmse_horizon.png, detections.png per sensor, "
                               "comparison.txt")]
    assert progress.quiet is False
    assert capsys.readouterr().out == ("\nsummary radar [deg]\nbreakdown radar\n\nsummary camera [deg]\nbreakdown camera\n"
                                       "\nradar versus camera\ncompared radar camera [deg]\n")


def test_one_sensor_writes_its_files_into_out_itself(tmp_path, recorded, capsys, monkeypatch):
    model = tmp_path / "w.msgpack"
    model.write_bytes(b"weights")
    out = tmp_path / "out"
    assert optimise.main(["--sensor", "camera", "--model", str(model), "--out", str(out), "--quiet"]) == 0
    assert [result for result, _ in recorded["written"]] == ["result camera"]
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json", "result.json"]
    (progress,) = _Progress.made
    assert progress.quiet is True and progress.lines == [
        f"loaded the predictor {model}", f"wrote {out}/: result.json, objective.png, rmse_horizon.png, detections.png"]
    assert recorded["solved"][0][2]["predictor"] == f"predictor {str(model)!r}"
    assert capsys.readouterr().out == "\nsummary camera [deg]\nbreakdown camera\n"
    monkeypatch.setattr(report, "write_run", lambda result, folder: {"param": None, "units": {}, "sensor": "suite"})
    assert optimise.main(["--sensor", "camera", "--out", str(out)]) == 0
    assert capsys.readouterr().out == "\nbox suite\nbreakdown suite\n"


def test_the_sensitivities_asked_reach_the_solve_and_the_background_import_fails_nothing(tmp_path, recorded,
                                                                                          monkeypatch):
    failed = []
    monkeypatch.setattr(threading, "excepthook", failed.append)
    before = set(threading.enumerate())
    argv = ["--sensor", "radar", "--sensitivity", "rain_mm_h, fog_visibility_m", "--out", str(tmp_path / "out")]
    assert optimise.main(argv) == 0
    for thread in set(threading.enumerate()) - before:
        thread.join(timeout=60)
    assert recorded["solved"][0][2]["sensitivity"] == ("rain_mm_h", "fog_visibility_m")
    assert failed == []


def test_a_worker_of_a_distributed_run_writes_to_scratch_and_prints_nothing(tmp_path, recorded, capsys, monkeypatch):
    joined, at_exit = [], []
    monkeypatch.setattr(_distributed, "initialize", lambda *a: joined.append(a))
    monkeypatch.setattr(_distributed, "is_writer", lambda: False)
    monkeypatch.setattr("atexit.register", lambda *a: at_exit.append(a))
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    out = tmp_path / "out"
    argv = ["--sensor", "radar", "--out", str(out), "--distributed", "--coordinator", "h:1", "--num-processes", "2",
            "--process-id", "1"]
    assert optimise.main(argv) == 0
    assert joined == [("h:1", 2, 1)] and not out.exists()
    (scratch,) = (tmp_path / "tmp").iterdir()  # the worker's outputs, removed when the process ends
    assert scratch.name.startswith("diffsense-worker-") and (scratch / "result.json").read_text() == "result radar"
    assert at_exit == [(shutil.rmtree, scratch, True)]
    assert capsys.readouterr().out == "" and _Progress.made[0].quiet is True
    monkeypatch.setattr(_distributed, "is_writer", lambda: True)
    assert optimise.main(argv) == 0
    assert (out / "result.json").exists() and capsys.readouterr().out == "\nsummary radar [deg]\nbreakdown radar\n"


def test_pareto_hands_the_weights_to_the_front_run(tmp_path, recorded, monkeypatch):
    asked = []
    monkeypatch.setattr(optimise, "pareto_run", lambda *a: asked.append(a) or 7)
    out = tmp_path / "out"
    assert optimise.main(["--param", "radar.hfov_deg=20:120", "--param", "radar.range_m=50:250", "--pareto", "0,0.01",
                          "--sensor", "radar", "--out", str(out)]) == 7
    ((problem, lambdas, folder, predictor, progress),) = asked
    assert dict(problem.params) == {"hfov_deg": (20.0, 120.0), "range_m": (50.0, 250.0)}  # one sensor: plain names
    assert lambdas == (0.0, 0.01) and folder == out and predictor == "predictor None"
    assert progress is _Progress.made[0] and recorded["solved"] == []


def _refused(argv, tmp_path) -> str:
    with pytest.raises(InputError) as e:
        optimise.main([*argv, "--out", str(tmp_path / "out")] if "--out" not in argv else argv)
    return str(e.value)


@pytest.mark.parametrize("argv, message", [
    (["--coordinator", "h:1"], "--coordinator, --num-processes and --process-id need --distributed"),
    (["--process-id", "0"], "--coordinator, --num-processes and --process-id need --distributed"),
    (["--num-processes", "2"], "--coordinator, --num-processes and --process-id need --distributed"),
    (["--max-memory-gb", "0"], "--max-memory-gb must be a positive number, got 0.0"),
    (["--max-memory-gb", "-1"], "--max-memory-gb must be a positive number, got -1.0"),
    (["--max-memory-gb", "nan"], "--max-memory-gb must be a positive number, got nan"),
    (["--max-memory-gb", "inf"], "--max-memory-gb must be a positive number, got inf"),
    (["--sensitivity", "rain_mm_h,snow"], ("--sensitivity: no sensitivity to 'snow' (known: rain_mm_h, "
                                           "fog_visibility_m, traffic_speed_kmh)")),
    (["--bogus"], "unrecognized arguments: --bogus"),
    (["--traffic-speed-offset-kmh", "-500"], ("sc01: a traffic speed offset of -500 km/h stops its slowest vehicle "
                                              "(start speed 35 km/h): every vehicle must start moving")),
    (["--miss-penalty", "big"], "argument --miss-penalty: invalid float value: 'big'"),
    (["--fog-visibility-m", "thick"], "argument --fog-visibility-m: invalid float value: 'thick'"),
    (["--traffic-speed-offset-kmh", "fast"], "argument --traffic-speed-offset-kmh: invalid float value: 'fast'"),
    (["--mc-samples", "8.5"], "argument --mc-samples: invalid int value: '8.5'"),
    (["--scenarios", "sc01", "--scenes", "highd:01_tracks.csv"],
     "--scenarios and --scenes exclude each other: recorded scenes replace the scenarios"),
])
def test_refusals_before_any_computation_by_whole_message(tmp_path, recorded, argv, message):
    assert _refused(argv, tmp_path) == message
    assert recorded["setup"] == [] and not (tmp_path / "out").exists()


def test_the_parser_s_defaults_and_choices():
    args = optimise._parser().parse_args([])
    assert (args.out, args.pareto, args.distributed, args.quiet, args.max_memory_gb) == ("out", None, False, False, None)
    assert optimise._parser().parse_args(["--pareto"]).pareto == ""  # the default weights
    for kind in ("auto", "mean-field", "mc", "relaxed-reference", "straight-through", "hard"):
        assert optimise._parser().parse_args(["--estimator", kind]).estimator == kind
    # Every flag with choices refuses others itself (how the choices are quoted varies with Python).
    for flag in ("--estimator", "--fill", "--profile", "--predictor-dtype", "--objective"):
        with pytest.raises(InputError, match=rf"^argument {flag}: invalid choice: 'Hard' \(choose from "):
            optimise._parser().parse_args([flag, "Hard"])


def test_files_in_the_way_are_refused(tmp_path, recorded):
    (tmp_path / "file").write_text("")
    assert _refused(["--out", str(tmp_path / "file")], tmp_path) == f"--out {tmp_path / 'file'} exists and is not a folder"
    assert _refused(["--model", str(tmp_path / "none.msgpack")], tmp_path) == f"--model {tmp_path / 'none.msgpack'}: not a file"
    assert recorded["setup"] == []


def test_recorded_scenes_leave_the_config_s_scenarios_unread(tmp_path, recorded):
    from _recorded_files import write_highd

    (tmp_path / "highd").mkdir()
    tracks = write_highd(tmp_path / "highd")
    config = tmp_path / "c.toml"
    config.write_text('[problem]\nscenarios = ["no-such-scenario"]\n')
    assert optimise.main(["--config", str(config), "--scenes", f"highd:{tracks}", "--out", str(tmp_path / "out")]) == 0
    assert _refused(["--config", str(config)], tmp_path).startswith("unknown scenario 'no-such-scenario'")
    assert _refused(["--scenes", f"highd:{tracks}", "--sensitivity", "traffic_speed_kmh"], tmp_path) == (
        f"no sensitivity to traffic_speed_kmh for recorded scenes (highd:{tracks}): they move at the speeds they "
        "were recorded at")


def test_the_console_script_ends_the_process_once_main_returns(monkeypatch):
    ran = []
    monkeypatch.setattr(cli, "run", lambda main, **kw: ran.append((main, kw)))
    optimise.console()
    assert ran == [(optimise.main, {"end_process": True})]


def test_the_memory_limit_defaults_to_half_the_machine(tmp_path, recorded, monkeypatch):
    estimate = [3.0e9]
    monkeypatch.setattr(_optimise, "memory_estimate_bytes", lambda problem: estimate[0])
    assert _refused(["--max-memory-gb", "2"], tmp_path) == (
        "the run needs an estimated 3.0 GB for its fixed data, over the limit of 2.0 GB (fewer variants or "
        "Monte-Carlo samples, or --max-memory-gb)")
    assert optimise.main(["--max-memory-gb", "3", "--out", str(tmp_path / "a")]) == 0  # at the limit: allowed
    estimate[0] = 3.0e9 + 1
    assert _refused(["--max-memory-gb", "3"], tmp_path).startswith("the run needs an estimated 3.0 GB")
    estimate[0] = 0.4e9
    assert optimise.main(["--max-memory-gb", "0.5", "--out", str(tmp_path / "b")]) == 0  # a limit under 1 GB
    estimate[0] = 3.0e9
    pages = {"SC_PAGE_SIZE": 4096, "SC_PHYS_PAGES": math.ceil(5.0e9 / 4096)}
    monkeypatch.setattr("os.sysconf", lambda name: pages[name])
    assert _refused([], tmp_path).startswith("the run needs an estimated 3.0 GB for its fixed data, over the limit of 2.5 GB")
