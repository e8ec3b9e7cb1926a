"""Sensor configs and parameters: the shipped profiles, a user's TOML, every physical domain and
constant checked at its edge (accepted on it, refused just past it, naming the culprit)."""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from diffsense import sensors
from diffsense.config import default_text
from diffsense.runtime import InputError

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("name", sensors.SENSORS)
def test_shipped_configs_load_and_their_specs_are_the_parameters(name):
    config = sensors.load_config(name)
    specs = sensors.param_specs(name, config)
    assert [s.name for s in specs] == [f.name for f in dataclasses.fields(config.params)]
    for spec in specs:
        # The mounting's defaults are the config's top-level keys (its [params] leave them None).
        own = getattr(config.params, spec.name)
        assert spec.default == (getattr(config, spec.name) if spec.name in sensors.MOUNT_NAMES else own)
        assert spec.contains(spec.default) and spec.lower < spec.upper and math.isfinite(spec.upper)
    hash(config)  # static under jit
    assert {"hfov_deg", "range_m", "vfov_deg", "tx_power_dbm", "noise_figure_db"} <= {
        s.name for s in sensors.param_specs("radar")}
    assert {"hfov_deg", "range_m", "width_px", "baseline_m"} <= {s.name for s in sensors.param_specs("camera")}


@pytest.mark.parametrize("name", sensors.SENSORS)
def test_every_domain_edge_is_accepted(name):
    config = sensors.load_config(name)
    for spec in sensors.param_specs(name):
        for value in (spec.lower + 1e-6 if spec.lower_open else spec.lower, spec.upper):
            assert getattr(sensors.make_params(config, **{spec.name: value}), spec.name) == value


@pytest.mark.parametrize("name, param, value", [
    ("radar", "hfov_deg", 0.0), ("radar", "hfov_deg", -1.0), ("radar", "hfov_deg", 360.5),
    ("radar", "range_m", -1.0), ("radar", "range_m", 0.0), ("radar", "range_m", math.nan),
    ("radar", "vfov_deg", 0.0), ("radar", "noise_figure_db", -1.0), ("radar", "tx_power_dbm", math.inf),
    ("camera", "hfov_deg", 400.0), ("camera", "baseline_m", 0.0), ("camera", "width_px", 0.0),
    ("camera", "range_m", -5.0), ("camera", "width_px", 0.5),
])
def test_a_value_outside_its_domain_is_refused_in_one_line_naming_it(name, param, value):
    with pytest.raises(InputError, match=f"{name} {param}") as err:
        sensors.make_params(sensors.load_config(name), **{param: value})
    assert "\n" not in str(err.value)
    spec = sensors.make_sensor(name).spec(param)
    assert spec.describe() in str(err.value)  # the domain with its unit


def test_a_batch_of_values_is_left_to_the_caller_and_the_rest_still_checked():
    # A solver may hold r as a batch (one value per vmapped lane): only scalars are checked.
    config = sensors.load_config("radar")
    for hfov in (np.array([30.0, 400.0]), np.array([400.0])):
        assert sensors.make_params(config, hfov_deg=hfov).hfov_deg is hfov
        batch = dataclasses.replace(config.params, hfov_deg=hfov)
        assert sensors.check_params(batch) is batch
    with pytest.raises(InputError, match="hfov_deg"):
        sensors.check_params(dataclasses.replace(config.params, hfov_deg=np.float64(400.0)))
    with pytest.raises(InputError, match="range_m"):
        sensors.make_params(config, hfov_deg=np.array([30.0, 400.0]), range_m=-5.0)


def test_unknown_names_are_refused_naming_them():
    radar = sensors.load_config("radar")
    with pytest.raises(InputError, match="'width_px'") as err:
        sensors.with_param(radar.params, "width_px", 1.0)
    assert "hfov_deg, vfov_deg, " in str(err.value)  # the known ones
    with pytest.raises(InputError, match="'lidar'"):
        sensors.param_specs("lidar")
    with pytest.raises(InputError, match="'lidar'"):
        sensors.load_config("lidar")
    with pytest.raises(InputError, match="'fancy'"):
        sensors.load_config("camera", profile="fancy")


_LOSSES = ("system_loss_db", "atmospheric_loss_db_per_km", "occlusion_loss_db", "range_accuracy_m",
           "azimuth_accuracy_deg", "range_resolution_m", "azimuth_resolution_deg")
_CONSTANT_EDGES = [  # (sensor, constant, the constraint's edge (accepted), just past it (refused))
    ("radar", "frequency_ghz", 1e-9, 0.0), ("radar", "noise_bandwidth_hz", 1e-9, 0.0),
    ("radar", "antenna_efficiency", 1e-9, 0.0), ("radar", "antenna_efficiency", 1.0, 1.0 + 1e-9),
    ("radar", "gain_beam_deg", 1e-9, 0.0), ("radar", "gain_beam_deg", 360.0, 360.0 + 1e-9),
    *[("radar", name, 0.0, -1e-9) for name in _LOSSES],
    ("camera", "disparity_error_px", 0.0, -1e-9), ("camera", "bearing_error_px", 0.0, -1e-9),
    ("camera", "min_width_px", 0.0, -1e-9), ("camera", "focal_length_px", 1e-9, 0.0),
    ("camera", "min_visible_fraction", 0.0, -1e-9), ("camera", "min_visible_fraction", 1.0, 1.0 + 1e-9),
    ("radar", "mount_y_m", 0.9, 1.5), ("camera", "mount_y_m", -0.9, -0.9 - 1e-9),
    ("radar", "mount_x_m", 4.2, 4.2 + 1e-9), ("camera", "mount_x_m", -2.3, -2.3 - 1e-9),
    ("radar", "yaw_deg", 180.0, 180.0 + 1e-9), ("camera", "yaw_deg", -180.0, -180.0 - 1e-9),
]


@pytest.mark.parametrize("name, constant, edge, past", _CONSTANT_EDGES)
def test_a_constant_on_its_edge_is_accepted_and_just_past_it_refused(name, constant, edge, past):
    config = sensors.load_config(name)
    assert getattr(dataclasses.replace(config, **{constant: edge}), constant) == edge
    with pytest.raises(InputError, match=f"^{name} {constant}"):
        dataclasses.replace(config, **{constant: past})


@pytest.mark.parametrize("name", sensors.SENSORS)
def test_every_soft_gate_temperature_must_be_positive(name):
    temperature = sensors.load_config(name).temperature
    for field in dataclasses.fields(temperature):
        assert getattr(dataclasses.replace(temperature, **{field.name: 1e-9}), field.name) == 1e-9
        with pytest.raises(InputError, match=f"^{name} temperature {field.name}"):
            dataclasses.replace(temperature, **{field.name: 0.0})


@pytest.mark.parametrize("edit, culprit", [
    (("snr_threshold_db = 13.2", "snr_threshold = 13.2"), "snr_threshold"),
    (("hfov_deg = 30.0", "hfov_deg = 0.0"), "hfov_deg"),
    (("snr_db = 1.0", "snr_db = 0.0"), "snr_db"),
    (("frequency_ghz = 77.0", 'frequency_ghz = "77"'), "frequency_ghz"),
    (("antenna_efficiency = 0.6", "antenna_efficiency = 1.5"), "antenna_efficiency"),
])
def test_a_malformed_user_config_is_refused_naming_the_file_and_the_key(tmp_path, edit, culprit):
    text = default_text("sensors/radar.toml")
    assert edit[0] in text
    path = tmp_path / "radar.toml"
    path.write_text(text.replace(edit[0], edit[1], 1))
    with pytest.raises(InputError, match=culprit) as err:
        sensors.load_config("radar", path)
    assert str(path) in str(err.value)


def test_a_user_config_replaces_only_its_keys(tmp_path):
    path = tmp_path / "radar.toml"
    path.write_text("snr_threshold_db = 10.0\n[params]\nrange_m = 150.0\n")
    config = sensors.load_config("radar", path)
    assert config.snr_threshold_db == 10.0 and config.params.range_m == 150.0
    assert config.rcs_car_dbsm == sensors.load_config("radar").rcs_car_dbsm
    assert sensors.make_sensor("radar", str(path)).config == config  # by name, as a problem builds it
    for text, culprit in (("mount_y_m = 1.5\n", "mount_y_m"), ("[params]\nyaw_deg = 10.0\n", "yaw_deg")):
        path.write_text(text)  # the mounting is a top-level key, and within its envelope
        with pytest.raises(InputError, match=culprit):
            sensors.Camera.from_toml(path)
    for x, y, yaw in ((-2.3, -0.9, -180.0), (4.2, 0.9, 180.0)):
        path.write_text(f"mount_x_m = {x}\nmount_y_m = {y}\nyaw_deg = {yaw}\n")
        config = sensors.Camera.from_toml(path).config
        assert (config.mount_x_m, config.mount_y_m, config.yaw_deg) == (x, y, yaw)


@pytest.mark.parametrize("cls", [sensors.Radar, sensors.Camera])
def test_a_sensor_class_builds_the_profile_it_is_asked_for(cls):
    paper, physical = cls.from_toml(profile="paper").config, cls.from_toml().config
    assert paper == sensors.load_config(cls.kind, profile="paper") and physical == sensors.load_config(cls.kind)
    assert paper != physical
    if cls is sensors.Radar:  # the paper's radar: gain of the fixed 30 deg beam
        assert (physical.gain_follows_hfov, paper.gain_follows_hfov) == (True, False)
    else:  # the paper's camera is an object list: no resolvability gate, Table II's accuracy
        assert paper.min_width_px == 0.0 < physical.min_width_px and not paper.accuracy_follows_hfov


def test_a_bad_sensor_config_on_the_cli_is_one_line_exit_2_nothing_written(tmp_path):
    path, culprit = tmp_path / "bad.toml", "snr_threshold_db"  # (every refusal: the loader's tests above)
    path.write_text("snr_threshold_db = nan\n")
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "diffsense.optimise", "--sensor-config", str(path), "--out", str(out)],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert lines[0].startswith("error: ") and culprit in lines[0] and str(path) in lines[0]
    assert not out.exists()
