"""Kills of the survivors of the third sensors mutation sample (seed 2, docs/mutation.md): the
bounds of the sensor configs' checks and the errors that name them, the camera's resolvable
range in the boresight report, and its fog and rain range kept in the scene's float type.

Hand values: the shipped camera (HFOV 30 deg, 1280 px, min_width_px 10) has k = 1280 / (pi / 6)
= 2444.6 px/rad, so a 1.8 m wide car is 10 px wide at R = 1.8 k / 10 = 440.0 m (small angle); the
paper radar's gain is that of a 30 x 15 deg beam, 17.4039 dBi (tests/test_sensors_radar_pinned.py);
rain of 25 mm/h alone gives a visibility of 1827 m (diffsense/sensors/_weather.py, tests/test_weather.py).
"""

from __future__ import annotations

import dataclasses
import math

import jax.numpy as jnp
import numpy as np
import pytest
from test_sensor_scenes import make_scene

from diffsense.runtime._errors import InputError
from diffsense.sensors import Weather
from diffsense.sensors._detect import p_detect
from diffsense.sensors._geometry import Tracks, polar
from diffsense.sensors._inspect import boresight_report
from diffsense.sensors._mount import mount_of
from diffsense.sensors._config import load_config
from diffsense.sensors._radar import radar_gain_dbi


def test_the_camera_resolves_a_car_out_to_where_it_is_min_width_px_wide():
    """440.03 m: 2 atan(w / 2R) k = min_width_px, and at a 2 mrad angle R = w k / min_width_px
    to 1.4e-6."""
    config = load_config("camera")
    k = 1280.0 / math.radians(30.0)
    report = boresight_report(config.params, config, 50.0)
    assert report["resolvable_range_m"] == pytest.approx(1.8 * k / 10.0, rel=1e-5)
    assert report["resolvable_range_m"] == pytest.approx(440.03, abs=0.01)
    at_limit = boresight_report(config.params, config, report["resolvable_range_m"])
    assert at_limit["width_px_at_range"] == pytest.approx(10.0, rel=1e-12)


def test_a_radar_gain_beam_may_be_the_full_circle():
    """The domain (0, 360] includes 360 deg, a beam 12 times the 30 deg one: 10 log10(12) =
    10.7918 dB less gain than its 17.4039 dBi."""
    config = dataclasses.replace(load_config("radar", None, "paper"), gain_beam_deg=360.0)
    assert float(radar_gain_dbi(config.params, config)) == pytest.approx(17.4039 - 10.7918, abs=1e-4)
    with pytest.raises(InputError, match=r"gain_beam_deg must be in \(0, 360\]"):
        dataclasses.replace(config, gain_beam_deg=360.5)


def test_a_camera_may_ask_for_the_whole_car_visible():
    """The domain [0, 1] includes min_visible_fraction 1: a lone car, unhidden, has the margin
    1 - 1 = 0 and is seen in hard mode."""
    config = dataclasses.replace(load_config("camera"), min_visible_fraction=1.0)
    scene = make_scene([[0.0, 20.0]], [[0.0, 0.0]])
    p = p_detect(scene, config.params, config, mode="hard")
    np.testing.assert_array_equal(np.asarray(p), [[1.0, 1.0]])
    with pytest.raises(InputError, match=r"min_visible_fraction must be in \[0, 1\]"):
        dataclasses.replace(config, min_visible_fraction=1.01)


def test_a_bad_constant_is_refused_by_name():
    """The error names the sensor and the constant (a negative loss, a zero temperature)."""
    radar, camera = load_config("radar"), load_config("camera")
    with pytest.raises(InputError, match="radar system_loss_db must be >= 0"):
        dataclasses.replace(radar, system_loss_db=-1.0)
    with pytest.raises(InputError, match="camera temperature width_px must be > 0"):
        dataclasses.replace(camera.temperature, width_px=0.0)


def test_the_cameras_weather_range_is_in_the_scenes_float_type():
    """Weather values arrive as arrays of E's type (float64 here); a float32 scene's range limit
    stays float32: 1827.06 m for 25 mm/h of rain, and with 300 m of fog 1 / (1/300 + 1/1827.06)
    m (extinctions add, so visibilities add as reciprocals)."""
    rate, fog = jnp.asarray(25.0, jnp.float64), jnp.asarray(300.0, jnp.float64)
    rain = Weather(rain_mm_h=rate).camera_range_m(jnp.float32)
    both = Weather(rain_mm_h=rate, fog_visibility_m=fog).camera_range_m(jnp.float32)
    assert rain.dtype == both.dtype == jnp.float32
    assert float(rain) == pytest.approx(1827.06, abs=0.05)
    assert float(both) == pytest.approx(1.0 / (1.0 / 300.0 + 1.0 / float(rain)), rel=1e-5)


def test_a_yaw_in_degrees_turns_the_boresight_by_that_many_degrees():
    """The radar (4.2 m ahead of the ego's centre) turned 90 deg left: a car 15 m to its left is
    on the boresight (azimuth 0), one 15 m ahead of it 90 deg to its right."""
    config = load_config("radar")
    mount = mount_of(dataclasses.replace(config.params, yaw_deg=90.0), config)
    scene = make_scene([[0.0, 4.2, 19.2]], [[0.0, 15.0, 0.0]])
    range_m, azimuth_rad = polar(Tracks.of(scene), mount)
    np.testing.assert_allclose(np.asarray(range_m)[1:, 0], [15.0, 15.0], rtol=1e-12)
    np.testing.assert_allclose(np.degrees(np.asarray(azimuth_rad)[1:, 0]), [0.0, -90.0], atol=1e-6)
