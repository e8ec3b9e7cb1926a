"""Sensor configs and parameters: loading, specs, domain refusals."""

from __future__ import annotations

import dataclasses
import math

import jax
import numpy as np
import pytest

from diffsense import sensors as sensor
from diffsense.config import default_text
from diffsense.runtime._errors import InputError
from tests._synthetic import straight_scene
from tests._toy_pipeline import ToySensor


@pytest.mark.parametrize("name", sensor.SENSORS)
def test_shipped_configs_load_and_specs_match_params(name):
    config = sensor.load_config(name)
    specs = sensor.param_specs(name, config)
    fields = [f.name for f in dataclasses.fields(config.params)]
    assert [s.name for s in specs] == fields
    for spec in specs:
        # The mounting's defaults are the config's top-level keys (its [params] leave them None).
        own = getattr(config.params, spec.name)
        assert spec.default == (getattr(config, spec.name) if spec.name in sensor.MOUNT_NAMES else own)
        assert spec.contains(spec.default)
        assert spec.lower < spec.upper and math.isfinite(spec.upper)
    hash(config)  # static under jit


def test_issue_parameters_are_differentiable():
    assert {"hfov_deg", "range_m", "vfov_deg", "tx_power_dbm", "noise_figure_db"} <= {
        s.name for s in sensor.param_specs("radar")}
    assert {"hfov_deg", "range_m", "width_px", "baseline_m"} <= {
        s.name for s in sensor.param_specs("camera")}


@pytest.mark.parametrize(
    "name, param, value",
    [
        ("radar", "hfov_deg", 0.0), ("radar", "hfov_deg", -1.0), ("radar", "hfov_deg", 360.5),
        ("radar", "range_m", -1.0), ("radar", "range_m", 0.0), ("radar", "range_m", math.nan),
        ("radar", "vfov_deg", 0.0), ("radar", "noise_figure_db", -1.0),
        ("radar", "tx_power_dbm", math.inf), ("camera", "hfov_deg", 400.0),
        ("camera", "baseline_m", 0.0), ("camera", "width_px", 0.0), ("camera", "range_m", -5.0),
    ],
)
def test_out_of_domain_values_are_refused_in_one_line(name, param, value):
    config = sensor.load_config(name)
    with pytest.raises(InputError, match=f"{name} {param} = .* outside its domain") as err:
        sensor.make_params(config, **{param: value})
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("name", sensor.SENSORS)
def test_domain_edges_are_accepted(name):
    config = sensor.load_config(name)
    for spec in sensor.param_specs(name):
        low = spec.lower + 1e-6 if spec.lower_open else spec.lower
        for value in (low, spec.upper):
            assert getattr(sensor.make_params(config, **{spec.name: value}), spec.name) == value


def test_unknown_parameter_sensor_mode_and_mismatch_are_refused():
    radar, camera = sensor.load_config("radar"), sensor.load_config("camera")
    with pytest.raises(InputError, match="unknown radar parameter 'width_px'"):
        sensor.with_param(radar.params, "width_px", 1.0)
    with pytest.raises(InputError, match="unknown sensor 'lidar'"):
        sensor.param_specs("lidar")
    with pytest.raises(InputError, match="do not match"):
        sensor.p_detect(None, radar.params, camera)


def test_a_plugged_in_sensor_is_never_handed_an_unknown_mode():
    # ToySensor reads any mode but "soft" as hard: the base class refuses the word first.
    scene = straight_scene(s0_m=[0.0, 30.0], lane=[1, 1], speed_mps=[25.0, 25.0], num_frames=3)
    for bad in ("SOFT", None, 1.0):
        with pytest.raises(InputError, match="unknown detection mode"):
            ToySensor().detect(scene, noise=jax.random.PRNGKey(0), mode=bad)
    assert float(ToySensor().detect(scene, noise=jax.random.PRNGKey(0), mode="hard").p_detect[0, 1]) == 1.0


def test_with_param_accepts_a_traced_value():
    config = sensor.load_config("camera")
    k = jax.jit(lambda w: sensor.camera_px_per_rad(sensor.with_param(config.params, "width_px", w)))
    assert float(k(2560.0)) == pytest.approx(2560.0 / math.radians(30.0))


def _write(tmp_path, name, text):
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    "edit, message",
    [
        (("snr_threshold_db = 13.2", "snr_threshold = 13.2"), "unknown key 'snr_threshold'"),
        (("hfov_deg = 30.0", "hfov_deg = 0.0"), "radar hfov_deg = 0 is outside"),
        (("snr_db = 1.0", "snr_db = 0.0"), "temperature snr_db must be > 0"),
        (("frequency_ghz = 77.0", 'frequency_ghz = "77"'), "expected a number"),
        (("antenna_efficiency = 0.6", "antenna_efficiency = 1.5"), "antenna_efficiency must be <= 1"),
    ],
)
def test_malformed_radar_config_is_refused_naming_the_file(tmp_path, edit, message):
    text = default_text("sensors/radar.toml")
    assert edit[0] in text
    path = _write(tmp_path, "radar", text.replace(edit[0], edit[1], 1))
    with pytest.raises(InputError, match=message) as err:
        sensor.load_config("radar", path)
    assert str(path) in str(err.value)


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
]


@pytest.mark.parametrize("name, constant, edge, past", _CONSTANT_EDGES)
def test_a_constant_on_its_edge_is_accepted_and_just_past_it_refused(name, constant, edge, past):
    config = sensor.load_config(name)
    assert getattr(dataclasses.replace(config, **{constant: edge}), constant) == edge
    with pytest.raises(InputError, match=f"^{name} {constant} must be "):
        dataclasses.replace(config, **{constant: past})


@pytest.mark.parametrize("name", sensor.SENSORS)
def test_every_soft_gate_temperature_must_be_positive(name):
    temperature = sensor.load_config(name).temperature
    for field in dataclasses.fields(temperature):
        assert getattr(dataclasses.replace(temperature, **{field.name: 1e-9}), field.name) == 1e-9
        with pytest.raises(InputError, match=f"^{name} temperature {field.name} must be > 0$"):
            dataclasses.replace(temperature, **{field.name: 0.0})


def test_a_refusal_states_the_domain_with_its_unit():
    with pytest.raises(InputError, match=r"^radar hfov_deg = 400 is outside its domain \(0, 360\] deg$"):
        sensor.make_params(sensor.load_config("radar"), hfov_deg=400.0)
    with pytest.raises(InputError, match=r"^camera width_px = 0.5 is outside its domain \[1, 16384\] px$"):
        sensor.make_params(sensor.load_config("camera"), width_px=0.5)


def test_batched_values_are_left_to_the_caller_and_the_rest_still_checked():
    config = sensor.load_config("radar")
    for hfov in (np.array([30.0, 400.0]), np.array([400.0])):  # a sweep's batch, of one too
        assert sensor.make_params(config, hfov_deg=hfov).hfov_deg is hfov
    with pytest.raises(InputError, match="radar range_m = -5 is outside"):
        sensor.make_params(config, hfov_deg=np.array([30.0, 400.0]), range_m=-5.0)


@pytest.mark.parametrize("name", sensor.SENSORS)
def test_a_mounting_outside_its_envelope_is_refused_naming_the_sensor(name):
    config = sensor.load_config(name)
    assert dataclasses.replace(config, mount_y_m=0.9).mount_y_m == 0.9
    with pytest.raises(InputError, match=rf"^{name} mount_y_m = 1.5 is outside its envelope \[-0.9, 0.9\] m$"):
        dataclasses.replace(config, mount_y_m=1.5)
