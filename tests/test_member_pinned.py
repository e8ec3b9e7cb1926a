"""One member's view for fusion (`sensors/_member.py`): the line-of-sight covariance against hand
values near the sensor and off the road's centre line, the temperature check on the way in, and
everything a custom member is handed."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_sensor_scenes import make_scene

from diffsense.runtime._errors import InputError
from diffsense.sensors._member import Covariance, line_of_sight_covariance, member_view
from diffsense.sensors._suite import Radar
from diffsense.sensors._weather import Weather
from tests._toy_pipeline import ToySensor

KEY = jax.random.key(6, impl="rbg")


@pytest.mark.parametrize("left_m", [0.0, 3.0])
def test_line_of_sight_covariance_close_to_the_sensor_and_off_the_centre_line(left_m):
    # The ego at (0, left_m) heading along x, the sensor 2 m ahead of it. Vehicle 1 sits 2 m ahead
    # of the sensor, vehicle 2 10 m to its left, vehicle 3 0.5 m to its left: its line of sight is
    # +y however close. Along the line of sight 0.5^2 + 1e-6 m^2; across (R^2 + 0.5^2) 0.01^2 +
    # 1e-6 m^2. The covariance moves with the road: the same for any left_m.
    tracks = SimpleNamespace(x_m=jnp.asarray([[0.0], [4.0], [2.0], [2.0]]),
                             y_m=jnp.asarray([[0.0], [0.0], [10.0], [0.5]]) + left_m,
                             heading_rad=jnp.zeros((4, 1)))
    ranges = (2.0, 2.0, 10.0, 0.5)
    cov = line_of_sight_covariance(tracks, 2.0, jnp.asarray([[r] for r in ranges]), 0.5, 0.01)
    along = 0.25 + 1e-6
    across = [(r * r + 0.25) * 1e-4 + 1e-6 for r in ranges]
    np.testing.assert_allclose(np.asarray(cov.xx)[0], [along, along, across[2], across[3]], rtol=1e-12)
    np.testing.assert_allclose(np.asarray(cov.yy)[0], [across[0], across[1], along, along], rtol=1e-12)
    np.testing.assert_allclose(np.asarray(cov.xy)[0], [0.0] * 4, atol=1e-15)


@pytest.mark.parametrize("temperature", [0.0, -1.0, float("nan")])
def test_member_view_refuses_a_temperature_that_is_not_positive(temperature):
    radar = Radar.from_toml()
    scene = make_scene([[0.0, 30.0]], [[0.0, 0.0]])
    with pytest.raises(InputError, match="temperature must be a positive number"):
        member_view(radar, scene, radar.defaults(), KEY, "soft", temperature)


class ShowsWhatItIsHanded(ToySensor):
    """The toy sensor whose view shows its inputs: rain halves its p of the other vehicles; its
    covariance is xx = range_m, xy = the rain rate, yy = the temperature (soft) or 100 (hard)."""

    def _detect(self, scene, r, noise, mode, temperature, weather):
        det = super()._detect(scene, r, noise, mode, temperature, weather)
        factor = 0.5 if weather.rain_mm_h > 0 else 1.0
        return dataclasses.replace(det, p_detect=det.p_detect.at[..., 1:].multiply(factor))

    def measurement_covariance(self, scene, r, mode, temperature, weather) -> Covariance:
        ones = jnp.ones(scene.x_m.shape)
        return Covariance(xx=r["range_m"] * ones, xy=weather.rain_mm_h * ones,
                          yy=(temperature if mode == "soft" else 100.0) * ones)


@pytest.mark.parametrize("mode", ["soft", "hard"])
def test_a_custom_member_is_handed_r_mode_temperature_and_weather(mode):
    toy, scene = ShowsWhatItIsHanded(), make_scene([[0.0, 5.0]], [[0.0, 0.0]])
    clear, _ = member_view(toy, scene, {"range_m": 7.0}, KEY, mode, 3.0)
    det, cov = member_view(toy, scene, {"range_m": 7.0}, KEY, mode, 3.0, Weather(rain_mm_h=25.0))
    assert float(clear.p_detect[0, 1]) > 0.5  # the car 5 m ahead is within the 7 m range
    assert float(det.p_detect[0, 1]) == pytest.approx(0.5 * float(clear.p_detect[0, 1]), rel=1e-12)
    yy = 3.0 if mode == "soft" else 100.0
    assert (float(cov.xx[0, 1]), float(cov.xy[0, 1]), float(cov.yy[0, 1])) == (7.0, 25.0, yy)
