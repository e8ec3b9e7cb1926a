"""Sensor profiles and user sensor configs: the paper's design reproduced, the physical one kept."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import pytest

import diffsense as ds
from diffsense.sensors import Camera, Radar, make_params
from diffsense.sensors._inspect import boresight_report
from diffsense.sensors._config import load_config

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("hfov", [30.0, 180.0])
def test_paper_radar_sees_100_m_at_every_hfov(hfov):
    config = load_config("radar", profile="paper")
    report = boresight_report(make_params(config, hfov_deg=hfov), config, 99.0)
    assert report["effective_range_m"] == pytest.approx(100.0)
    assert report["p_detect_hard"] == 1.0
    # The gain is that of the 30 x 15 deg beam: 10 log10(0.6 * 4 pi / (30 * 15 deg^2)) [dBi].
    beam_sr = math.radians(30.0) * math.radians(15.0)
    assert report["gain_dbi"] == pytest.approx(10 * math.log10(0.6 * 4 * math.pi / beam_sr), abs=1e-9)


def test_physical_radar_is_unchanged():
    config = load_config("radar")
    wide = boresight_report(make_params(config, hfov_deg=180.0), config, 99.0)
    narrow = boresight_report(make_params(config, hfov_deg=30.0), config, 99.0)
    # Six times the beam costs 20 log10(6) = 15.56 dB of two-way gain and a factor 6^(-1/2) of the
    # SNR-limited range (R^4 law): 122.7 m -> 50.1 m (plus the atmosphere's small share).
    assert narrow["snr_db"] - wide["snr_db"] == pytest.approx(20 * math.log10(6.0), abs=0.02)
    assert narrow["effective_range_m"] == pytest.approx(100.0)
    assert 49.0 < wide["effective_range_m"] < 51.0


def test_paper_camera_is_an_object_list_with_table_ii_accuracy():
    paper, physical = load_config("camera", profile="paper"), load_config("camera")
    assert paper.min_width_px == 0.0 and not paper.accuracy_follows_hfov
    for hfov in (30.0, 180.0):
        report = boresight_report(make_params(paper, hfov_deg=hfov), paper, 80.0)
        # sigma_Z = Z^2 * 0.5 px / (2400 px * 0.12 m) at Z = 80 m: 11.11 m, whatever the HFOV.
        assert report["depth_sigma_m"] == pytest.approx(80.0**2 * 0.5 / (2400 * 0.12), rel=1e-6)
        assert report["effective_range_m"] == pytest.approx(100.0)
    wide = boresight_report(make_params(physical, hfov_deg=180.0), physical, 80.0)
    k = 1280 / math.pi
    assert wide["depth_sigma_m"] == pytest.approx(80.0**2 * 0.5 / (k * 0.12), rel=1e-6)


@pytest.mark.parametrize("cls", [Radar, Camera])
def test_a_sensor_class_builds_the_profile_it_is_asked_for(cls):
    paper, physical = cls.from_toml(profile="paper").config, cls.from_toml().config
    assert paper == load_config(cls.kind, profile="paper") and physical == load_config(cls.kind)
    assert paper != physical
    if cls is Camera:  # the paper's camera is an object list: no resolvability gate
        assert paper.min_width_px == 0.0 < physical.min_width_px


def test_problem_profile_sets_the_paper_fill():
    assert ds.Problem(profile="paper").fill == "zero" and ds.Problem().fill == "hold"
    assert ds.Problem(profile="paper", fill="interp").fill == "interp"


def test_user_sensor_config_replaces_only_its_keys(tmp_path):
    path = tmp_path / "radar.toml"
    path.write_text("snr_threshold_db = 10.0\n[params]\nrange_m = 150.0\n")
    config = load_config("radar", path)
    assert config.snr_threshold_db == 10.0 and config.params.range_m == 150.0
    assert config.rcs_car_dbsm == load_config("radar").rcs_car_dbsm
    problem = ds.Problem(sensor_config=str(path))
    assert problem.make_sensor().config.snr_threshold_db == 10.0


@pytest.mark.parametrize("text, needle", [
    ("snr_threshold = 10.0\n", "unknown key 'snr_threshold'"),
    ("snr_threshold_db = 'high'\n", "snr_threshold_db: expected a number"),
    ("snr_threshold_db = nan\n", "snr_threshold_db: expected a finite number"),
])
def test_bad_sensor_config_is_one_line_exit_2_nothing_written(tmp_path, text, needle):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "diffsense.optimise", "--sensor-config", str(path), "--out", str(out)],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0] and str(path) in lines[0]
    assert not out.exists()
