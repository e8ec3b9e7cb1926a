"""Kills of the survivors of the second sensors mutation sample (seed 1, docs/mutation.md): float
types kept through the camera's fixed accuracy and the radar's rain loss, a custom suite member
seen in soft mode, every parameter's documentation, the focal length's check at its bound, and
fuse_members refusing drawn probabilities that do not match its members."""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest
from test_sensors_suite_pinned import KEY, ToyWithCovariance, _scene

from diffsense.runtime._errors import InputError
from diffsense.sensors import Camera, Radar, Weather
from diffsense.sensors._camera import camera_accuracy_px_per_rad
from diffsense.sensors._fusion import Suite, fuse_members
from diffsense.sensors._member import member_view
from diffsense.sensors._config import CameraConfig, load_config
from diffsense.sensors._params import CameraParams


def test_the_paper_cameras_fixed_accuracy_keeps_the_parameters_float_type():
    config = load_config("camera", None, "paper")
    assert not config.accuracy_follows_hfov  # the paper's object-list camera: accuracy fixed
    defaults = Camera(config).defaults()
    params = CameraParams(**{f.name: jnp.float32(defaults[f.name]) for f in dataclasses.fields(CameraParams)})
    k = camera_accuracy_px_per_rad(params, config)
    assert k.dtype == jnp.float32 and float(k) == config.focal_length_px


def test_rain_loss_takes_the_range_float_type():
    # Weather values arrive as arrays of E's type (float64 here); the loss follows the range's.
    rain = Weather(rain_mm_h=jnp.asarray(25.0, jnp.float64))
    loss = rain.radar_loss_db(jnp.asarray([50.0, 150.0], jnp.float32))
    assert loss.dtype == jnp.float32 and np.all(np.asarray(loss) > 0)


def test_a_custom_member_is_asked_in_the_mode_it_is_given():
    # The toy sees within range_m with a logistic gate in soft mode: the car 20 m ahead at range
    # 20 m is on the gate's centre, p = 1/2, where hard mode gives 0 or 1.
    toy = ToyWithCovariance()
    r = toy.defaults() | {"range_m": 20.0}
    soft, _ = member_view(toy, _scene(), r, KEY, "soft", 1.0)
    hard, _ = member_view(toy, _scene(), r, KEY, "hard", 1.0)
    assert float(soft.p_detect[0, 2]) == pytest.approx(0.5, abs=1e-6)
    assert float(hard.p_detect[0, 2]) in (0.0, 1.0)


def test_every_parameter_is_documented_and_a_suites_names_its_member():
    for sensor in (Radar.from_toml(), Camera.from_toml()):
        assert all(isinstance(s.doc, str) and s.doc for s in sensor.param_specs())
    suite = Suite((Radar.from_toml(), Camera.from_toml()))
    docs = {s.name: s.doc for s in suite.param_specs()}
    assert docs["radar.hfov_deg"].startswith("radar: ") and docs["camera.width_px"].startswith("camera: ")


def test_the_focal_length_needs_only_to_be_positive():
    config = load_config("camera", None, "paper")
    assert dataclasses.replace(config, focal_length_px=0.5).focal_length_px == 0.5
    with pytest.raises(InputError, match="focal_length_px must be > 0"):
        dataclasses.replace(config, focal_length_px=0.0)


def test_fuse_members_wants_one_drawn_probability_per_member():
    toy = ToyWithCovariance()
    views = [member_view(toy, _scene(), toy.defaults(), KEY, "hard", 1.0)] * 2
    with pytest.raises(ValueError):
        fuse_members(_scene(), views, [views[0][0].p_detect])
