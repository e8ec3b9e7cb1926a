"""Weather wired into the sensors and the objective: hand-checked effects, clear weather unchanged
bit for bit, finite values and gradients over the ODD's range."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffsense as ds
from diffsense import sensors
from diffsense.sensors import Weather
from tests._laws import threshold_config
from tests._synthetic import straight_scene


def _car_at(range_m: float, mount_x_m: float):
    """The ego and a 4.5 m x 1.8 m car `range_m` ahead of the sensor in its lane, one frame."""
    return straight_scene([0.0, mount_x_m + range_m], [1, 1], [0.0, 0.0], num_frames=1)


def test_rain_shortens_the_radar():
    config = threshold_config("radar")  # the threshold law: a car in or out
    params = sensors.make_params(config, hfov_deg=30.0, range_m=200.0)
    # At 115 m a car's SNR is ~14.3 dB, ~1.1 dB above the 13.2 dB threshold (the link budget in
    # configs/sensors/radar.toml: 122.7 m SNR-limited range). 25 mm/h costs 2 x 11.41 dB/km x
    # 0.115 km = 2.62 dB two-way (ITU-R P.838-3 at 77 GHz): the car drops out.
    scene = _car_at(115.0, config.mount_x_m)
    clear = sensors.radar_p_detect(scene, params, config, mode="hard")[0, 1]
    rain = sensors.radar_p_detect(scene, params, config, mode="hard", weather=Weather(rain_mm_h=25.0))[0, 1]
    assert float(clear) == 1.0 and float(rain) == 0.0
    near = sensors.radar_p_detect(_car_at(60.0, config.mount_x_m), params, config, mode="hard",
                          weather=Weather(rain_mm_h=25.0))[0, 1]
    assert float(near) == 1.0


def test_fog_shortens_the_camera():
    config = threshold_config("camera")
    params = sensors.make_params(config, hfov_deg=60.0)
    fog = Weather(fog_visibility_m=50.0)  # Koschmieder: contrast range = visibility for C0 = 1
    for r, seen in ((40.0, 1.0), (60.0, 0.0)):
        p = sensors.camera_p_detect(_car_at(r, config.mount_x_m), params, config, mode="hard", weather=fog)[0, 1]
        assert float(p) == seen
    assert float(sensors.camera_p_detect(_car_at(60.0, config.mount_x_m), params, config, mode="hard")[0, 1]) == 1.0


@pytest.fixture(scope="module")
def objectives():
    predictor = ds.predictors.init_predictor()
    base = dict(scenarios=["sc01"], variants=1, prediction_stride_frames=40, predictor=predictor)
    radar = ds.objective(ds.Problem(**base))
    camera = ds.objective(ds.Problem(sensor="camera", **base))
    zero = ds.objective(ds.Problem(weather={"rain_mm_h": 0.0}, **base))
    return radar, camera, zero


def test_zero_rain_is_clear_weather_bit_for_bit(objectives):
    radar, _, zero = objectives
    # one compiled program per mode, run on both objectives (op by op, it is many small
    # programs); the same program on other data, so equality still means equal weather
    value = eqx.filter_jit(lambda E, mode: E({"hfov_deg": 45.0}, mode=mode))
    assert float(value(zero, "soft")) == float(value(radar, "soft"))
    assert float(value(zero, "hard")) == float(value(radar, "hard"))


def _value_in_weather(w, E):
    return eqx.tree_at(lambda o: o.weather, E, w)({"hfov_deg": 45.0})


# At module level, E an argument: one compilation per objective serves every weather below.
_value_and_weather_gradient = eqx.filter_jit(jax.value_and_grad(_value_in_weather))


@pytest.mark.parametrize("rain, fog", [(0.0, 10.0), (200.0, 10.0), (0.0, 1e4), (0.1, math.inf), (200.0, math.inf)])
def test_finite_value_and_gradient_over_the_odd(objectives, rain, fog):
    for E in objectives[:2]:
        w = Weather(rain_mm_h=jnp.full((1,), rain), fog_visibility_m=jnp.full((1,), fog))
        v, g = _value_and_weather_gradient(w, E)
        assert np.isfinite(float(v))
        assert all(np.all(np.isfinite(np.asarray(x))) for x in jax.tree.leaves(g))


def test_weather_input_is_checked():
    with pytest.raises(ds.InputError, match="rain_mm_h"):
        ds.Problem(weather={"rain_mm_h": -1.0})
    with pytest.raises(ds.InputError, match="'snow'"):
        ds.Problem(weather={"snow": 1.0})
    with pytest.raises(ds.InputError, match="paper"):
        ds.Problem(profile="paper", weather={"rain_mm_h": 5.0})
