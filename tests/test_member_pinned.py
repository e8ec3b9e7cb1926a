"""One member's view for fusion (`sensors/_member.py`): the line-of-sight covariance against hand
values near the sensor and off the road's centre line, and the temperature check on the way in."""

from __future__ import annotations

from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_sensor_scenes import make_scene

from diffsense.errors import InputError
from diffsense.sensors._member import line_of_sight_covariance, member_view
from diffsense.sensors._suite import Radar

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
