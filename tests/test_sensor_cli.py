"""`diffsense inspect`: the link budget's numbers, JSON, the coverage plot, and one-line refusals
naming their culprit, exit code 2."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from _laws import THRESHOLD

from diffsense.cli import run
from diffsense.cli.sensors import main


def _json(capsys, *argv):
    assert main(["inspect", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_radar_report_on_boresight(capsys):
    out = _json(capsys, "--sensor", "radar", "--hfov", "30,60", "--at-range", "100", "--config", THRESHOLD["radar"])
    narrow, wide = out["results"]
    assert narrow["snr_db"] == pytest.approx(16.78, abs=0.01)
    assert narrow["snr_db"] - wide["snr_db"] == pytest.approx(6.0206, abs=1e-3)
    assert narrow["effective_range_m"] == 100.0 < narrow["snr_range_m"]
    assert wide["effective_range_m"] == pytest.approx(wide["snr_range_m"])
    assert wide["effective_range_m"] < 100.0
    assert narrow["p_detect_hard"] == 1.0 and wide["p_detect_hard"] == 0.0


def test_under_swerling_i_the_report_gives_the_ranges_of_pd_0_5_and_0_9(capsys):
    out = _json(capsys, "--sensor", "radar", "--hfov", "30,60", "--at-range", "100")  # the physical law
    narrow, wide = out["results"]
    # Pd = Pfa^(1/(1+SNR)) at Pfa 1e-6: 12.77 dB for Pd 0.5, 21.14 dB for 0.9; the SNR falls as
    # 40 log10 R (and 0.8 dB/km of air), so the ranges stand 10^(8.37/40) = 1.62 apart
    assert narrow["snr_pd50_db"] == pytest.approx(12.771, abs=1e-3)
    assert narrow["range_pd50_m"] / narrow["range_pd90_m"] == pytest.approx(1.619, rel=3e-3)
    assert narrow["range_pd50_m"] / wide["range_pd50_m"] == pytest.approx(2**0.5, rel=1e-2)  # 6 dB less gain
    assert wide["effective_range_m"] == pytest.approx(wide["range_pd50_m"])
    assert wide["effective_range_m"] < 100.0 == narrow["effective_range_m"]
    assert 0.0 < wide["p_detect_hard"] < narrow["p_detect_hard"] < 1.0  # a probability, not a gate


def test_camera_report_and_table(capsys):
    out = _json(capsys, "--sensor", "camera", "--hfov", "30", "--at-range", "50")
    row = out["results"][0]
    assert row["px_per_rad"] == pytest.approx(2444.6, abs=0.1)
    assert row["depth_sigma_m"] == pytest.approx(50**2 * 0.5 / (row["px_per_rad"] * 0.12))
    assert main(["inspect", "--sensor", "camera", "--set", "range_m=80"]) == 0
    text = capsys.readouterr().out
    assert "px_per_rad" in text and "depth_sigma_m" in text and "at 80 m" in text


def test_coverage_plot_is_written(tmp_path, capsys):
    path = tmp_path / "coverage.png"
    assert main(["inspect", "--sensor", "radar", "--hfov", "30,90,180", "--plot", str(path)]) == 0
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["coverage.png"]  # no temporary left over


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--sensor", "radar", "--hfov", "0"], "hfov_deg = 0"),
        (["--sensor", "radar", "--hfov", "400"], "hfov_deg = 400"),
        (["--sensor", "radar", "--set", "range_m=-3"], "range_m = -3"),
        (["--sensor", "camera", "--hfov", "thirty"], "'thirty'"),
        (["--sensor", "camera", "--set", "focal=3"], "'focal'"),
        (["--sensor", "sonar"], "'sonar'"),
        (["--sensor", "radar", "--at-range", "-1"], "--at-range"),
        (["--sensor", "radar", "--plot", "out.jpeg"], "'out.jpeg'"),
        (["--sensor", "radar", "--config", "missing.toml"], "missing.toml"),
    ],
)
def test_bad_input_is_one_line_and_exit_code_2(tmp_path, monkeypatch, capsys, argv, message):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exit_:
        run(lambda: main(["inspect", *argv]))
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and message in err and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


def test_module_entry_point_exits_2_without_traceback():
    proc = subprocess.run([sys.executable, "-m", "diffsense.sensors", "inspect", "--sensor",
                           "radar", "--hfov", "-5"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.startswith("error: ") and proc.stderr.count("\n") == 1 and "hfov_deg = -5" in proc.stderr
