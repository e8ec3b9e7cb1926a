"""Kills the survivors of the fifth sensors mutation sample (seed 4, 120 mutants at 2b4bda0;
docs/mutation.md): a suite's member views at the default temperature, the line-of-sight
covariance of a vehicle at the sensor itself, a sensor's parameter defaults from its own
config, a domain's printed form, and the probe scene's and boresight report's fields."""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
from test_sensor_scenes import make_scene

from diffsense.scene import CAR
from diffsense.sensors import make_sensor
from diffsense.sensors._config import load_config
from diffsense.sensors._fusion import Suite
from diffsense.sensors._inspect import boresight_report, probe_scene
from diffsense.sensors._member import line_of_sight_covariance
from diffsense.sensors._suite import Camera, Radar
from tests.test_sensors_suite_pinned import ToyWithCovariance

KEY = jax.random.key(4, impl="rbg")


def test_member_views_default_to_temperature_one():
    # The toy member's soft p is sigmoid(margin / (2 T)); a car 20 m ahead with range 21 m has
    # margin 1 m: p = sigmoid(1/2) = 0.6224593 at T = 1 (sigmoid(1/4) = 0.5621765 at T = 2).
    x = np.array([[0.0, 20.0], [0.5, 20.5]])
    suite = Suite((ToyWithCovariance(),), names=("front",))
    (det, _), = suite.member_views(make_scene(x, np.zeros_like(x), kind=[CAR] * 2), {"front.range_m": 21.0}, KEY)
    np.testing.assert_allclose(np.asarray(det.p_detect)[:, 1], [1.0 / (1.0 + math.exp(-0.5))] * 2, rtol=1e-12)


def test_line_of_sight_covariance_of_a_vehicle_at_the_sensor():
    # The ego at the origin heading along x, the sensor 2 m ahead of it: vehicle 1 sits at the
    # sensor (no line of sight: straight ahead is taken), vehicle 2 10 m to its left. Along the
    # line of sight 0.5^2 + 1e-6 m^2; across (R^2 + 0.5^2) 0.01^2 + 1e-6 m^2.
    tracks = SimpleNamespace(x_m=jnp.asarray([[0.0], [2.0], [2.0]]), y_m=jnp.asarray([[0.0], [0.0], [10.0]]),
                             heading_rad=jnp.zeros((3, 1)))
    cov = line_of_sight_covariance(tracks, 2.0, jnp.asarray([[2.0], [0.0], [10.0]]), 0.5, 0.01)
    along = 0.25 + 1e-6
    across = [(r * r + 0.25) * 1e-4 + 1e-6 for r in (2.0, 0.0, 10.0)]
    np.testing.assert_allclose(np.asarray(cov.xx)[0], [along, along, across[2]], rtol=1e-12)
    np.testing.assert_allclose(np.asarray(cov.yy)[0], [across[0], across[1], along], rtol=1e-12)
    np.testing.assert_allclose(np.asarray(cov.xy)[0], [0.0, 0.0, 0.0], atol=1e-15)


def test_a_sensor_offers_its_own_configs_defaults():
    for cls, kind in ((Radar, "radar"), (Camera, "camera")):
        config = load_config(kind)
        narrow = dataclasses.replace(config, params=dataclasses.replace(config.params, hfov_deg=45.0))
        specs = {s.name: s for s in cls(narrow).param_specs()}
        assert specs["hfov_deg"].default == 45.0 != config.params.hfov_deg


def test_a_domain_prints_as_an_interval_with_its_unit():
    radar = make_sensor("radar")
    assert radar.spec("hfov_deg").describe() == "(0, 360] deg"
    assert radar.spec("tx_power_dbm").describe() == "[-30, 40] dBm"


def test_probe_scene_indices_are_int32_and_the_report_names_its_range():
    scene = probe_scene(jnp.asarray([10.0]), jnp.zeros(1), length_m=4.5, width_m=1.8)
    assert scene.kind.dtype == scene.role.dtype == jnp.int32  # as every simulated scene's
    config = load_config("radar")
    report = boresight_report(config.params, config, 99.0)
    assert report["at_range_m"] == 99.0 and report["hfov_deg"] == config.params.hfov_deg
