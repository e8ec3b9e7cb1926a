"""`diffsense scene`: the figure written atomically, the scene's JSON, bad input one line and exit 2."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

import diffsense as ds
import diffsense.cli.scene as cli


@pytest.fixture(autouse=True)
def _keep_jax_settings(monkeypatch):
    # The CLI switches x64 off for speed; in-process that would leak into other tests.
    monkeypatch.setattr(cli, "setup_jax", lambda **kwargs: None)


def test_show_writes_the_figure_and_prints_json(tmp_path, capsys):
    out = tmp_path / "figs" / "sc01.png"
    assert cli.main(["show", "sc01", "--out", str(out), "--json", "--variant", "1", "--seed", "1"]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in out.parent.iterdir()] == ["sc01.png"]  # no temporary left behind
    data = json.loads(capsys.readouterr().out)
    assert data["dt_s"] == 0.1 and data["road"]["name"] == "us101" and data["road"]["num_lanes"] == 6
    roles = [v["role"] for v in data["vehicles"]]
    assert roles == ["ego", "target", "lead", "target_lead", "adjacent"]
    for v in data["vehicles"]:
        assert {"role", "length_m", "width_m", "s_m", "d_m"} <= set(v)
        assert len(v["s_m"]) == len(v["d_m"]) == 201 and v["length_m"] > 0 and v["width_m"] > 0
    target = data["vehicles"][1]
    assert target["d_m"][0] - target["d_m"][-1] == pytest.approx(3.66, abs=1e-3)  # to the right


def test_variants_differ_by_seed(capsys):
    cli.main(["show", "sc02", "--json", "--variant", "1", "--seed", "1"])
    a = json.loads(capsys.readouterr().out)
    cli.main(["show", "sc02", "--json", "--variant", "1", "--seed", "2"])
    b = json.loads(capsys.readouterr().out)
    assert a["vehicles"][0]["s_m"] != b["vehicles"][0]["s_m"]
    target = a["vehicles"][1]
    assert target["d_m"][-1] - target["d_m"][0] == pytest.approx(3.66, abs=1e-3)  # sc02: to the left


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["show", "sc09", "--json"], "'sc09'"),
        (["show", "sc01"], "--out"),
        (["show", "sc01", "--out", "x.txt"], "'x.txt'"),
        (["show", "sc01", "--json", "--variant", "-1"], "--variant"),
        (["show", "sc01", "--json", "--seed", "x"], "'x'"),
        (["draw"], "'draw'"),
    ],
)
def test_bad_input_is_one_line(argv, needle):
    with pytest.raises(ds.InputError, match=needle) as e:
        cli.main(argv)
    assert "\n" not in str(e.value)


def test_exit_code_2_without_traceback(tmp_path):
    out = tmp_path / "never.png"
    proc = subprocess.run(
        [sys.executable, "-m", "diffsense.scene", "show", "nope", "--out", str(out)],
        capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 2
    assert proc.stderr.startswith("error: unknown scenario 'nope'") and proc.stderr.count("\n") == 1
    assert "Traceback" not in proc.stderr and not out.exists()


def test_generate_is_the_training_traffic_command(capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["generate", "--help"])
    assert e.value.code == 0 and capsys.readouterr().out.startswith("usage: python -m diffsense.scene generate ")
