"""`diffsense optimise`: what the flags run and what the command writes and prints. In-process, with
`diffsense.optimise` (and `diffsense.pareto`) replaced by stand-ins that return a result by hand:
the problems solved per sensor, result.json and comparison.txt published as one set, the tables
printed from what was written, --quiet, a distributed run's worker, the Pareto front; every
refusal before any computation as one `error:` line naming its culprit, exit 2, nothing written.
Under `slow`, small real runs and their result.json."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from flax import nnx

import diffsense as ds
from diffsense import report, runtime
from diffsense.cli import optimise, run
from diffsense.predictors import CSLSTM, save_weights

ROOT = Path(__file__).resolve().parents[1]
SUITE = str(ROOT / "configs/suites/radar_camera_d4.toml")


def _line(sensor: str, e: float) -> dict:
    """result.json of a one-parameter run, as far as the tables read it."""
    return {"sensor": sensor, "param": "hfov_deg", "units": {"hfov_deg": "deg"}, "interval": [30.0, 180.0],
            "sweep": [{"r": 30.0, "E_hard": e + 1, "E_soft": e + 1.5}, {"r": 180.0, "E_hard": e + 2, "E_soft": e + 2}],
            "on_bound": False, "r_star": {"hfov_deg": 55.5}, "E_hard_star": e, "E_soft_star": e + 0.25,
            "reference": {"answer_on": "E_hard"}, "evaluations": {"objective": 7, "gradient": 3},
            "wall_s": {"compile": 1.0, "run": 2.0}, "notes": [], "flags": [], "by_scenario": {}}


BOX = {"sensor": "radar", "param": None, "r_star": {"hfov_deg": 40.0, "range_m": 120.0},
       "units": {"hfov_deg": "deg", "range_m": "m"}, "E_hard_star": 4.0, "E_soft_star": 4.125, "reference": None,
       "by_scenario": {}, "box": {"cost_weight": 0.0, "gradient": {"hfov_deg": 0.01, "range_m": -0.02},
                                  "on_bound": {"hfov_deg": "", "range_m": ""}, "cost": 12.0, "J_star": 4.0,
                                  "source": "start", "counts": {"soft": 4, "hard": 2}}}


class _Solved:
    """What `diffsense.optimise` returns, as far as the command line reads it: no curves, no figures."""
    curves = None

    def __init__(self, content: dict):
        self.content = content

    def to_json(self) -> dict:
        return self.content


@pytest.fixture
def solved(monkeypatch):
    """The problems `diffsense.optimise` is asked to solve, with its keyword arguments."""
    asked = []

    def solve(problem, **kw):
        asked.append((problem, kw))
        box = len(problem.params) > 1
        return _Solved(BOX if box else _line(problem.sensor_kind, 3.0 if problem.sensor_kind == "radar" else 2.5))

    monkeypatch.setattr(ds, "optimise", solve)
    return asked


def _main(argv, capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as e:
        run(lambda: optimise.main(argv))
    out, err = capsys.readouterr()
    return e.value.code, out, err


def test_both_sensors_are_solved_and_published_with_their_comparison(tmp_path, solved, capsys):
    out = tmp_path / "out"
    code, printed, _ = _main(["--sensor", "both", "--param", "hfov", "--interval", "30", "180", "--out", str(out)], capsys)
    assert code == 0
    assert [(p.sensor_kind, dict(p.params)) for p, _ in solved] == [
        ("radar", {"hfov_deg": (30.0, 180.0)}), ("camera", {"hfov_deg": (30.0, 180.0)})]
    assert sorted(p.name for p in out.iterdir()) == ["camera", "comparison.txt", "manifest.json", "radar"]
    written = {s: json.loads((out / s / "result.json").read_text()) for s in ("radar", "camera")}
    assert written == {"radar": _line("radar", 3.0), "camera": _line("camera", 2.5)}
    comparison = report.comparison_table(written, unit="deg")
    assert (out / "comparison.txt").read_text() == comparison + "\n"
    for content in written.values():
        assert report.summary_table(content, unit="deg") in printed
    assert printed.endswith(comparison + "\n")


def test_one_sensor_writes_into_out_itself_and_quiet_prints_only_the_table(tmp_path, solved, capsys):
    out = tmp_path / "out"
    argv = ["--sensor", "camera", "--sensitivity", "rain_mm_h, fog_visibility_m", "--out", str(out)]
    code, printed, err = _main([*argv, "--quiet"], capsys)
    assert (code, err) == (0, "")
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json", "report.html", "result.json"]
    assert printed == "\n" + report.summary_table(_line("camera", 2.5), unit="deg") + "\n\n"
    (_, kw), = solved
    assert kw["sensitivity"] == ("rain_mm_h", "fog_visibility_m")
    assert _main(argv, capsys)[2] != ""  # without --quiet: the stages on stderr


def test_several_parameters_print_the_box_table(tmp_path, solved, capsys):
    argv = ["--sensor", "radar", "--param", "hfov=20:120", "--param", "range=50:250", "--out", str(tmp_path / "o")]
    code, printed, _ = _main(argv, capsys)
    assert code == 0 and [dict(p.params) for p, _ in solved] == [{"hfov_deg": (20.0, 120.0), "range_m": (50.0, 250.0)}]
    assert printed.startswith("\n" + report.box_table(BOX) + "\n")


def test_a_config_file_s_values_reach_the_problem_and_flags_override_them(tmp_path, solved, capsys):
    path = tmp_path / "mine.toml"
    path.write_text("[problem]\nvariants = 3\n")  # a partial config: the rest keep their defaults
    for argv, variants in ((["--config", str(path)], 3), (["--config", str(path), "--variants", "5"], 5)):
        assert _main([*argv, "--out", str(tmp_path / "o")], capsys)[0] == 0
        problem = solved[-1][0]
        assert problem.keywords()["variants"] == variants and dict(problem.params) == {"hfov_deg": (30.0, 180.0)}


def test_a_worker_of_a_distributed_run_writes_to_scratch_and_prints_nothing(tmp_path, solved, capsys, monkeypatch):
    joined, at_exit = [], []
    monkeypatch.setattr(runtime, "initialize", lambda *a: joined.append(a))
    monkeypatch.setattr(runtime, "is_writer", lambda: False)
    monkeypatch.setattr("atexit.register", lambda *a: at_exit.append(a))
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    out = tmp_path / "out"
    argv = ["--sensor", "radar", "--out", str(out), "--distributed", "--coordinator", "h:1", "--num-processes", "2",
            "--process-id", "1"]
    assert _main(argv, capsys)[:2] == (0, "")
    assert joined == [("h:1", 2, 1)] and not out.exists()
    (scratch,) = (tmp_path / "tmp").iterdir()  # the worker's outputs, removed when the process ends
    assert json.loads((scratch / "result.json").read_text()) == _line("radar", 3.0)
    assert at_exit == [(shutil.rmtree, scratch, True)]
    monkeypatch.setattr(runtime, "is_writer", lambda: True)
    code, printed, _ = _main(argv, capsys)
    assert code == 0 and (out / "result.json").exists() and report.summary_table(_line("radar", 3.0), unit="deg") in printed


PARETO = {"sensor": "radar+camera", "judged_on": "E_hard", "currency": "EUR", "units": {"radar.hfov_deg": "deg"},
          "lambdas": [0.0, 0.01], "front": [1, 0], "evaluations": {"soft": 20, "hard": 9}, "wall_s": 1.0,
          "cloud": {"cost": [1.0, 3.0], "E_hard_m": [6.0, 4.0]},
          "designs": [{"lambda": lam, "r_star": {"radar.hfov_deg": r}, "E_hard_m": e, "cost": c, "on_front": True}
                      for lam, r, e, c in ((0.0, 30.0, 4.0, 3.0), (0.01, 60.0, 6.0, 1.0))]}


class _Front:
    """What `diffsense.pareto` returns, as far as the command line reads it."""
    sensor, judged_on, currency = "radar+camera", "E_hard", "EUR"

    def to_dict(self) -> dict:
        return PARETO


@pytest.mark.parametrize("weights, lambdas", [("0,0.01", (0.0, 0.01)), (None, ds.study.DEFAULT_LAMBDAS)])
def test_pareto_publishes_the_front_and_prints_its_table(tmp_path, capsys, monkeypatch, weights, lambdas):
    asked = []
    monkeypatch.setattr(ds, "pareto", lambda problem, lambdas, **kw: asked.append((problem, lambdas)) or _Front())
    out = tmp_path / "out"
    code, printed, _ = _main(["--suite", SUITE, "--pareto", *([weights] if weights else []), "--out", str(out)], capsys)
    assert code == 0 and [tuple(lam) for _, lam in asked] == [tuple(lambdas)]
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json", "pareto.json", "pareto.png"]
    assert json.loads((out / "pareto.json").read_text()) == PARETO
    assert printed == "\n" + report.pareto_table(PARETO) + "\n"


def test_a_failed_front_publishes_nothing(tmp_path, capsys, monkeypatch):
    def pareto(problem, lambdas, **kw):
        raise ds.InputError("no front")

    monkeypatch.setattr(ds, "pareto", pareto)
    out = tmp_path / "out"
    code, _, err = _main(["--suite", SUITE, "--pareto", "--out", str(out), "--quiet"], capsys)
    assert (code, err) == (2, "error: no front\n")
    assert not out.exists() or not [p for p in out.iterdir() if not p.name.startswith(".")]


def _files(tmp_path):
    (tmp_path / "file").write_text("")
    (tmp_path / "junk.tar").write_bytes(b"not a checkpoint")
    (tmp_path / "bad.toml").write_text("[problem\nsensor = 'radar'\n")
    (tmp_path / "unknown.toml").write_text("[problem]\nvariantz = 8\n")


@pytest.mark.parametrize("argv, culprit", [
    (["--coordinator", "h:1"], "--coordinator"),
    (["--max-memory-gb", "0"], "--max-memory-gb"),
    (["--max-memory-gb", "1e-9"], "--max-memory-gb"),
    (["--estimator", "mc", "--mc-samples", "10000000"], "--max-memory-gb"),  # terabytes: over half the machine
    (["--estimator", "Hard"], "'Hard'"),
    (["--miss-penalty", "big"], "'big'"),
    (["--sensitivity", "rain_mm_h,snow"], "'snow'"),
    (["--traffic-speed-offset-kmh", "-500"], "-500 km/h"),
    (["--scenarios", "sc01", "--scenes", "highd:01_tracks.csv"], "--scenes"),
    (["--param", "warp"], "'warp'"),
    (["--param", "hfov=20:120", "--interval", "30", "180"], "--interval"),
    (["--interval", "180", "30"], "lo < hi"),
    (["--interval", "30", "400"], "hfov_deg"),
    (["--scenarios", "sc99"], "'sc99'"),
    (["--scenarios", "sc01,sc01"], "sc01"),
    (["--variants", "0"], "variants"),
    (["--seed", "9223372036854775808"], "seed"),
    (["--steps", "30,abc"], "--steps"),
    (["--steps", "200,300"], "[30.0, 180.0]"),
    (["--tau", "-1"], "--tau"),
    (["--dense-check", "0"], "dense_check"),
    (["--model", "/nonexistent/weights.msgpack"], "/nonexistent/weights.msgpack"),
    (["--model", "{tmp}/junk.tar"], "junk.tar"),
    (["--config", "{tmp}/bad.toml"], "bad.toml"),
    (["--config", "{tmp}/unknown.toml"], "problem.variantz"),
    (["--out", "{tmp}/file"], "{tmp}/file"),
    (["--suite", SUITE, "--sensor", "radar"], "--sensor"),
    (["--pareto", "--sensor", "both"], "--pareto"),
    (["--pareto", "--sensitivity", "rain_mm_h"], "--pareto"),
    (["--pareto", "0,x"], "--pareto"),
])
def test_refusals_before_any_computation(tmp_path, solved, capsys, argv, culprit):
    _files(tmp_path)
    argv, culprit = [a.format(tmp=tmp_path) for a in argv], culprit.format(tmp=tmp_path)
    code, printed, err = _main([*argv, *([] if "--out" in argv else ["--out", str(tmp_path / "out")])], capsys)
    assert (code, printed) == (2, "") and err.startswith("error: ") and err.count("\n") == 1, err
    assert culprit in err and solved == [] and not (tmp_path / "out").exists()


def test_recorded_scenes_leave_the_config_s_scenarios_unread(tmp_path, solved, capsys):
    from _recorded_files import write_highd

    (tmp_path / "highd").mkdir()
    tracks = write_highd(tmp_path / "highd")
    config = tmp_path / "c.toml"
    config.write_text('[problem]\nscenarios = ["no-such-scenario"]\n')
    assert _main(["--config", str(config), "--scenes", f"highd:{tracks}", "--out", str(tmp_path / "o")], capsys)[0] == 0
    code, _, err = _main(["--scenes", f"highd:{tracks}", "--sensitivity", "traffic_speed_kmh"], capsys)
    assert code == 2 and "traffic_speed_kmh" in err and f"highd:{tracks}" in err


@pytest.fixture(scope="module")
def weights(tmp_path_factory) -> Path:
    """A randomly initialised CS-LSTM: the command's plumbing needs no trained weights."""
    path = tmp_path_factory.mktemp("weights") / "random.msgpack"
    save_weights(path, CSLSTM(rngs=nnx.Rngs(0)))
    return path


@pytest.mark.slow
def test_a_small_run_writes_a_consistent_result(weights, tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["--model", str(weights), "--scenarios", "sc05", "--variants", "1", "--steps", "30,105,180",
            "--dense-check", "15", "--sensor-config", "configs/sensors/laws/radar_threshold.toml",
            "--out", str(out), "--quiet"]
    assert _main(argv, capsys)[0] == 0
    result = json.loads((out / "result.json").read_text())
    assert result["param"] == "hfov_deg" and result["interval"] == [30.0, 180.0] and result["units"] == {"hfov_deg": "deg"}
    assert [p["r"] for p in result["sweep"]] == [30.0, 105.0, 180.0]
    assert result["E_hard_star"] <= min(p["E_hard"] for p in result["sweep"])
    assert result["evaluations"]["objective"] + result["evaluations"]["gradient"] <= 20
    dense = result["dense_check"]  # 30, 45, ..., 180: 11 hard evaluations
    assert dense["evaluations"] == 11 and dense["step"] == 15.0
    # The threshold law is deterministic: its reference is E_hard, with no standard error.
    assert dense["E_ref_best_se"] == 0.0 and dense["E_ref_star"] == pytest.approx(result["E_hard_star"], rel=1e-12)
    assert dense["E_ref_best"] <= min(p["E_hard"] for p in result["sweep"]) + 1e-12
    assert sorted(p.name for p in out.iterdir()) == ["detections.png", "manifest.json", "objective.png", "report.html",
                                                     "result.json", "rmse_horizon.png"]


@pytest.mark.slow
def test_the_hard_estimator_searches_the_best_bracket(weights, tmp_path, capsys):
    out = tmp_path / "hard"
    argv = ["--model", str(weights), "--scenarios", "sc05", "--variants", "1", "--estimator", "hard",
            "--steps", "30,105,180", "--out", str(out), "--quiet"]
    assert _main(argv, capsys)[0] == 0
    result = json.loads((out / "result.json").read_text())
    assert result["evaluations"] == {"objective": 20, "gradient": 0}
    assert result["E_hard_star"] <= min(p["E_hard"] for p in result["sweep"])
    assert result["bracket"][0] <= result["r_star"]["hfov_deg"] <= result["bracket"][1]
