"""Weather reaches the sensors' detections: each public sensor function passes it on, the radar
subtracts the rain's two-way loss from its SNR (once, with a minus sign), fog caps the camera's
range. The weather physics itself is pinned in tests/test_weather.py."""

from __future__ import annotations

import jax
import numpy as np
import pytest
from test_sensor_scenes import make_scene

from diffsense import sensors as sensor
from diffsense.sensors._geometry import Tracks
from diffsense.sensors._radar import _radar_terms
from diffsense.sensors._weather import Weather

RADAR = sensor.load_config("radar")
CAMERA = sensor.load_config("camera")
KEY = jax.random.key(5, impl="rbg")
RAIN = Weather(rain_mm_h=25.0)
FOG = Weather(fog_visibility_m=50.0)


def _ahead(config, range_m):
    return make_scene([[0.0, config.mount_x_m + range_m]], [[0.0, 0.0]])


def test_rain_lowers_the_radar_snr_margin_by_its_two_way_loss():
    # ITU-R P.838-3 at 77 GHz, 25 mm/h: 10.99 (V) to 11.41 (H) dB/km, so 2.20 to 2.28 dB over the
    # two-way 100 m path.
    tracks = Tracks.of(_ahead(RADAR, 100.0))
    terms = jax.jit(lambda t, rain: _radar_terms(t, RADAR.params, RADAR, "soft", 1.0,
                                                 Weather(rain_mm_h=rain)))
    clear = float(terms(tracks, 0.0)[0][2][0][1, 0])
    rainy = float(terms(tracks, 25.0)[0][2][0][1, 0])
    assert clear - rainy == pytest.approx(float(RAIN.radar_loss_db(np.float64(100.0))), rel=1e-9)
    assert 2.19 < clear - rainy < 2.29


@pytest.mark.parametrize("name", ["radar", "camera"])
def test_every_sensor_function_passes_the_weather_on(name):
    # Radar at 60 deg: a car at 87 m sits on the SNR edge (p ~ 1/2); rain takes ~2 dB off it.
    # Camera: a car at 60 m is seen in clear weather and lost in 50-m fog (hard).
    config = RADAR if name == "radar" else CAMERA
    params = sensor.make_params(config, hfov_deg=60.0)
    scene = _ahead(config, 87.0 if name == "radar" else 60.0)
    weather = RAIN if name == "radar" else FOG
    mode = "soft" if name == "radar" else "hard"
    p_fn = sensor.radar_p_detect if name == "radar" else sensor.camera_p_detect
    det_fn = sensor.radar_detect if name == "radar" else sensor.camera_detect
    device = (sensor.Radar if name == "radar" else sensor.Camera)(config)  # the Sensor protocol
    clear = float(p_fn(scene, params, config, mode=mode)[0, 1])
    for p in (p_fn(scene, params, config, mode=mode, weather=weather),
              det_fn(scene, params, config, KEY, mode=mode, weather=weather).p_detect,
              device.detect(scene, {"hfov_deg": 60.0}, KEY, mode=mode, weather=weather).p_detect):
        assert float(p[0, 1]) < clear - 0.3, (clear, float(p[0, 1]))

