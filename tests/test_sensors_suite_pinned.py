"""A suite of sensors as the optimiser builds it: the parameters r reach its members, a custom
member's own covariance is fused, member names, profiles, and the refusals that guard them.

Hand values: the toy sensor sees a vehicle when it is closer than range_m along x (p 1 or 0 in
hard mode); the paper radar's gain is fixed at the 30 deg beam (configs/sensors/paper/radar.toml).
"""

from __future__ import annotations

import math

import jax
import numpy as np
import pytest
from test_sensor_scenes import make_scene

from diffsense.runtime._errors import InputError
from diffsense.scene import CAR
from diffsense.sensors import Radar, make_sensor, register, sensor_names
from diffsense.sensors import _sensor as sensor_module
from diffsense.sensors._fusion import Suite
from diffsense.sensors._member import Covariance, member_view
from diffsense.sensors._config import load_config
from diffsense.sensors._params import with_param
from tests._toy_pipeline import ToySensor

KEY = jax.random.key(3, impl="rbg")


class ToyWithCovariance(ToySensor):
    """The toy sensor with a fixed measurement covariance: 4 m^2 in x, 9 m^2 in y, 1 m^2 across."""

    def measurement_covariance(self, scene, r, mode, temperature, weather) -> Covariance:
        ones = np.ones(scene.x_m.shape)
        return Covariance(xx=4.0 * ones, xy=1.0 * ones, yy=9.0 * ones)


def _scene():
    """Ego at 0 and cars 5, 20 and 40 m ahead (two frames)."""
    x = np.array([[0.0, 5.0, 20.0, 40.0], [0.5, 5.5, 20.5, 40.5]])
    return make_scene(x, np.zeros_like(x), kind=[CAR] * 4)


def test_suite_hands_r_to_its_members():
    suite = Suite((ToyWithCovariance(),), names=("front",))
    near = suite.detect(_scene(), {"front.range_m": 10.0}, KEY, mode="hard")
    far = suite.detect(_scene(), {"front.range_m": 30.0}, KEY, mode="hard")
    # range 10 m sees only the car 5 m ahead, 30 m also the one 20 m ahead (the ego is known)
    np.testing.assert_array_equal(np.asarray(near.p_detect), [[1, 1, 0, 0]] * 2)
    np.testing.assert_array_equal(np.asarray(far.p_detect), [[1, 1, 1, 0]] * 2)


def test_a_custom_member_is_fused_with_its_own_covariance():
    toy = ToyWithCovariance()
    det, cov = member_view(toy, _scene(), toy.defaults(), KEY, "hard", 1.0)
    np.testing.assert_array_equal(np.asarray(det.p_detect), [[1, 1, 1, 1]] * 2)  # all within 50 m
    assert (float(cov.xx[0, 1]), float(cov.xy[1, 2]), float(cov.yy[1, 3])) == (4.0, 1.0, 9.0)


def test_member_names_are_non_empty_without_a_dot():
    radar = Radar.from_toml()
    for bad in ("front.left", ".", ""):
        with pytest.raises(InputError, match="non-empty and has no '.'"):
            Suite((radar,), names=(bad,))
    assert Suite((radar,), names=("front_left",)).names == ("front_left",)


def test_profiles_reach_the_sensor_and_a_sensor_object_takes_none():
    assert Radar.from_toml().config.gain_follows_hfov is True
    assert Radar.from_toml(profile="paper").config.gain_follows_hfov is False
    radar = Radar.from_toml()
    assert make_sensor(radar) is radar
    with pytest.raises(InputError, match="carries its own constants"):
        make_sensor(radar, profile="paper")


def test_unknown_parameter_lists_the_known_ones():
    params = load_config("radar").params
    with pytest.raises(InputError, match=r"known: hfov_deg, vfov_deg, "):
        with_param(params, "hfov", 30.0)


def test_a_suite_of_names_takes_the_profile_to_every_member():
    suite = make_sensor(["radar", "camera"], profile="paper")
    configs = [m.config for m in suite.members]
    assert configs == [load_config("radar", profile="paper"), load_config("camera", profile="paper")]


def test_the_registry_names_and_builds_a_factory_without_arguments(monkeypatch):
    monkeypatch.setattr(sensor_module, "_REGISTRY", dict(sensor_module._REGISTRY))
    before = sensor_names()  # radar and camera first (other tests may have added theirs)
    assert before[:2] == ("radar", "camera") and "toy_2" not in before
    register("toy_2", ToySensor)  # '_' and digits are allowed; ToySensor() takes no arguments
    assert sensor_names() == (*before, "toy_2")
    assert isinstance(make_sensor("toy_2"), ToySensor)  # the default profile calls factory()
    for bad in ("", "_", "a.b", "a-b", "a b"):  # "_" alone names nothing: no letter or digit
        with pytest.raises(InputError, match="letters, digits and '_'"):
            register(bad, ToySensor)
    assert sensor_names() == (*before, "toy_2")


def test_detect_defaults_to_temperature_1():
    # The toy's soft gate is sigmoid((range_m - distance) / (2 T)): the car 20 m ahead with a
    # 22 m range is 1 / (1 + e^-1) = 0.7311 at T = 1, 1 / (1 + e^-0.5) = 0.6225 at T = 2.
    toy, r = ToySensor(), {"range_m": 22.0}
    p = float(toy.detect(_scene(), r, KEY).p_detect[0, 2])
    assert p == pytest.approx(1.0 / (1.0 + math.exp(-1.0)), rel=1e-6)
    assert p == float(toy.detect(_scene(), r, KEY, temperature=1.0).p_detect[0, 2])
