"""The main CLI: bad input gives one line and exit code 2 with nothing written; a small run
writes a complete, consistent result."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from flax import nnx

from diffsense import cli as _cli
from diffsense.cli.optimise import main
from diffsense.predictors import CSLSTM, save_weights

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(autouse=True)
def _no_user_cache(monkeypatch):
    monkeypatch.setenv("DIFFSENSE_NO_CACHE", "1")


@pytest.fixture(scope="module")
def weights(tmp_path_factory) -> Path:
    """A randomly initialised CS-LSTM: the CLI's plumbing does not need trained weights."""
    path = tmp_path_factory.mktemp("weights") / "random.msgpack"
    save_weights(path, CSLSTM(rngs=nnx.Rngs(0)))
    return path


def _run(argv, capsys) -> tuple[int, str]:
    with pytest.raises(SystemExit) as e:
        _cli.run(lambda: main(argv))
    return e.value.code, capsys.readouterr().err


@pytest.mark.parametrize(
    "args, needle",
    [
        (["--param", "warp"], "unknown radar parameter 'warp'"),
        (["--param", "width", "--sensor", "radar"], "unknown radar parameter 'width'"),
        (["--interval", "180", "30"], "lo < hi"),
        (["--interval", "30", "400"], "outside the domain of hfov_deg"),
        (["--param", "range", "--interval", "-5", "100"], "outside the domain of range_m"),
        (["--scenarios", "sc99"], "unknown scenario 'sc99'"),
        (["--variants", "0"], "variants must be an integer in [1,"),
        (["--scenarios", "sc01,sc01"], "scenario named twice: sc01"),
        (["--scenarios", ""], "empty name"),
        (["--seed", "9223372036854775808"], "seed must be an integer"),
        (["--steps", "30,abc"], "--steps must be comma-separated numbers"),
        (["--tau", "-1"], "--tau must be a positive number"),
        (["--model", "/nonexistent/weights.msgpack"], "/nonexistent/weights.msgpack"),
        (["--dense-check", "0"], "dense_check must be a positive step"),
        (["--dense-check", "1e-6"], "over 100,000 points"),
    ],
)
def test_bad_input_is_one_line_exit_2_nothing_written(args, needle, tmp_path, capsys):
    out = tmp_path / "out"
    code, err = _run(args + ["--out", str(out)], capsys)
    assert code == 2
    assert err.startswith("error: ") and err.count("\n") == 1, err
    assert needle in err
    assert not out.exists()


def test_malformed_and_unknown_key_configs(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("[problem\nsensor = 'radar'\n")
    code, err = _run(["--config", str(bad), "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "malformed TOML" in err
    unknown = tmp_path / "unknown.toml"
    text = (ROOT / "configs/optimise/default.toml").read_text().replace("variants = 8", "variantz = 8")
    unknown.write_text(text)
    code, err = _run(["--config", str(unknown), "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "unknown key 'problem.variantz'" in err


def test_invalid_checkpoint(tmp_path, capsys):
    junk = tmp_path / "junk.tar"
    junk.write_bytes(b"not a checkpoint")
    code, err = _run(["--model", str(junk), "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "junk.tar" in err and not (tmp_path / "o").exists()


def test_real_process_prints_no_traceback(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "diffsense.optimise", "--interval", "180", "30", "--out", str(tmp_path / "o")],
        cwd=ROOT, capture_output=True, text=True, timeout=300,
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and proc.stderr.startswith("error: ")


@pytest.mark.slow
def test_small_run_writes_a_consistent_result(weights, tmp_path, capsys):
    out = tmp_path / "run"
    code, _ = _run(["--model", str(weights), "--scenarios", "sc05", "--variants", "1",
                    "--steps", "30,105,180", "--dense-check", "15", "--out", str(out), "--quiet"], capsys)
    assert code == 0
    result = json.loads((out / "result.json").read_text())
    for key in ("param", "interval", "sensor", "r_star", "E_soft_star", "E_hard_star", "sweep",
                "evaluations", "wall_s", "on_bound", "config", "versions"):
        assert key in result
    assert result["param"] == "hfov_deg" and result["interval"] == [30.0, 180.0]
    assert set(result["r_star"]) == {"hfov_deg"} and result["units"] == {"hfov_deg": "deg"}
    assert [p["r"] for p in result["sweep"]] == [30.0, 105.0, 180.0]
    assert result["E_hard_star"] <= min(p["E_hard"] for p in result["sweep"])
    assert result["evaluations"]["objective"] + result["evaluations"]["gradient"] <= 20
    assert set(result["wall_s"]) >= {"compile", "run"}
    dense = result["dense_check"]  # 30, 45, ..., 180: 11 hard evaluations
    assert dense["evaluations"] == 11 and dense["step"] == 15.0
    # The shipped threshold law is deterministic: its reference is E_hard, with no standard error.
    assert dense["objective"] == "reference" and dense["E_ref_best_se"] == 0.0 and dense["E_ref_star_se"] == 0.0
    assert dense["E_ref_best"] <= min(p["E_hard"] for p in result["sweep"]) + 1e-12
    assert dense["E_ref_star"] == pytest.approx(result["E_hard_star"], rel=1e-12)
    assert dense["E_ref_star_minus_best"] == pytest.approx(result["E_hard_star"] - dense["E_ref_best"])
    assert any(n == "dense check: " + dense["verdict"] for n in result["notes"])
    assert dense["in_basin"] == dense["verdict"].startswith("r* lies in the basin")
    for name in ("objective.png", "rmse_horizon.png", "detections.png"):
        assert (out / name).stat().st_size > 1000
    assert sorted(p.name for p in out.iterdir()) == ["detections.png", "manifest.json", "objective.png",
                                                     "result.json", "rmse_horizon.png"]


def test_config_file_values_reach_the_run_and_flags_override_them(tmp_path):
    from diffsense.cli.optimise import _parser, problems

    path = tmp_path / "mine.toml"
    path.write_text("[problem]\nvariants = 3\nprediction_stride_frames = 6\n")  # a partial config
    (p,) = problems(_parser().parse_args(["--config", str(path)]))
    assert p.variants == 3 and p.prediction_stride_frames == 6 and p.params == {"hfov_deg": (30.0, 180.0)}
    (p,) = problems(_parser().parse_args(["--config", str(path), "--variants", "5", "--fill", "zero"]))
    assert p.variants == 5 and p.fill == "zero" and p.prediction_stride_frames == 6
    (p,) = problems(_parser().parse_args(["--param", "range", "--tau", "0.5"]))
    assert p.params == {"range_m": (30.0, 200.0)} and p.solve.tau_schedule == (2.0, 1.0, 0.5)


@pytest.mark.slow
def test_hard_estimator_searches_the_best_bracket(weights, tmp_path, capsys):
    out = tmp_path / "hard"
    code, _ = _run(["--model", str(weights), "--scenarios", "sc05", "--variants", "1", "--estimator", "hard",
                    "--steps", "30,105,180", "--out", str(out), "--quiet"], capsys)
    assert code == 0
    result = json.loads((out / "result.json").read_text())
    assert result["evaluations"] == {"objective": 20, "gradient": 0}
    assert result["E_hard_star"] <= min(p["E_hard"] for p in result["sweep"])
    assert result["bracket"][0] <= result["r_star"]["hfov_deg"] <= result["bracket"][1]
    assert result["notes"][0].startswith("hard estimator: no gradient")


def test_reserve_polish_config_is_the_default_but_for_that_key():
    from diffsense import config as cfgio
    from diffsense.study._settings import load_settings

    default = load_settings()
    reserve = load_settings(ROOT / "configs/optimise/reserve_polish.toml")
    assert not default.solve.reserve_polish and reserve.solve.reserve_polish
    assert cfgio.replace(reserve, solve=cfgio.replace(reserve.solve, reserve_polish=False)) == default
