"""One sensor's view of a scene with its measurement covariance: what fusion needs.

`Detections` carry no variance, so fusion asks each member for `member_view`: the member's
`Detections` (the same numbers `Sensor.detect` gives) and the covariance of its measured
position in the world frame, per frame and vehicle [m^2].

Radar and camera measure along the line of sight (range with sigma_r, stereo depth with
sigma_Z) and across it (azimuth or bearing with sigma_a [rad]); the measured position is the
measured range along the line of sight turned by the angle error. Its covariance is
sigma_r^2 u u^T + (R^2 + sigma_r^2) sigma_a^2 v v^T, with u the unit line of sight from the
sensor to the vehicle, v = u turned by +90 deg and R the true range: the across error is the
product of the independent range and angle errors (to second order in them: for the camera at
140 deg, a car 112 m ahead has sigma_Z = 99 m and R^2 alone gives 56 % of the variance). The
sigmas are those the sensor draws its noise with (`_radar_terms`, `_camera_terms`), computed in
the same pass as the detections, so fusion costs no second occlusion scan. A custom sensor takes
part in fusion by defining `measurement_covariance(scene, r, mode, temperature, weather) -> Covariance`.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from diffsense.runtime import InputError
from diffsense.scene import EGO_INDEX, Scene
from diffsense.sensors._camera import Camera, _camera_terms
from diffsense.sensors._datatypes import Detections
from diffsense.sensors._gates import check_mode, check_temperature, p_from_gates
from diffsense.sensors._geometry import safe_norm, sensor_pose, to_world
from diffsense.sensors._measure import (
    KeyOrNoise,
    _noise,
    _transposed,
    own_and_padding,
    tracks_of,
)
from diffsense.sensors._mount import Mount, mount_of
from diffsense.sensors._params import CameraParams, RadarParams
from diffsense.sensors._radar import Radar, _radar_terms
from diffsense.sensors._sensor import Sensor, params_of
from diffsense.sensors._weather import CLEAR, Weather

# A variance floor [m^2] (1 mm standard deviation, far below any sensor's accuracy): a camera's
# depth and bearing sigmas vanish at zero range, and fusion inverts the covariance.
VARIANCE_FLOOR_M2 = 1e-6


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Covariance:
    """The covariance of a measured world position per (frame, vehicle) [m^2], each [T, V].

    Attributes:
        xx: variance of x [m^2].
        xy: covariance of x and y [m^2].
        yy: variance of y [m^2].
    """

    xx: Float[Array, "*N T V"]
    xy: Float[Array, "*N T V"]
    yy: Float[Array, "*N T V"]

    def det(self) -> Float[Array, "*N T V"]:
        """The determinant xx yy - xy^2 [m^4]."""
        return self.xx * self.yy - self.xy * self.xy


def line_of_sight_covariance(tracks, mount: Mount | float, range_m, along_sigma_m, across_sigma_rad) -> Covariance:
    """World covariance [T, V] of a range measured with sigma `along_sigma_m` [m] along the line
    of sight and turned by an angle error of sigma `across_sigma_rad` [rad]; arrays [V, T] in."""
    sx, sy, yaw = sensor_pose(tracks, mount)
    dx, dy = tracks.x_m - sx, tracks.y_m - sy
    r = safe_norm(dx, dy)
    ok = r > 0
    inv_r = 1.0 / jnp.where(ok, r, 1.0)
    ux = jnp.where(ok, dx * inv_r, jnp.cos(yaw))  # co-located: straight ahead, as `to_world`
    uy = jnp.where(ok, dy * inv_r, jnp.sin(yaw))
    along = along_sigma_m**2 + VARIANCE_FLOOR_M2
    across = (range_m**2 + along_sigma_m**2) * across_sigma_rad**2 + VARIANCE_FLOOR_M2
    xx = along * ux * ux + across * uy * uy
    yy = along * uy * uy + across * ux * ux
    xy = (along - across) * ux * uy
    return Covariance(xx=_transposed(xx), xy=_transposed(xy), yy=_transposed(yy))


def _physics_view(terms, scene: Scene, params, config, noise: KeyOrNoise, mode, temperature, weather):
    """`detect_of` of `_measure.py` plus the covariance, from one call of `terms`.

    The detections are computed exactly as `detect_of` computes them (tests pin the equality).
    """
    mode = check_mode(mode)
    check_temperature(temperature)
    tracks = tracks_of(scene)
    eps = jax.lax.optimization_barrier(jnp.swapaxes(_noise(noise, scene), -1, -2))
    gates, range_m, _, range_sigma, azimuth_sigma = terms(tracks, params, config, mode, temperature, weather)
    mount = mount_of(params, config)
    x, y = to_world(tracks, mount, range_m + range_sigma * eps[0], azimuth_sigma * eps[1])
    known = (jnp.arange(x.shape[0]) == EGO_INDEX)[:, None] | ~tracks.present
    x = jnp.where(known, tracks.x_m, x)
    y = jnp.where(known, tracks.y_m, y)
    det = Detections(p_detect=own_and_padding(tracks, p_from_gates(gates, mode)),
                     x_m=_transposed(x), y_m=_transposed(y))
    return det, line_of_sight_covariance(tracks, mount, range_m, range_sigma, azimuth_sigma)


def member_view(sensor: Sensor, scene: Scene, r: dict[str, Any], noise: KeyOrNoise, mode, temperature,
                weather: Weather = CLEAR) -> tuple[Detections, Covariance]:
    """`sensor`'s Detections [T, V] of `scene` in `weather` with r complete, and their world covariance."""
    
    if isinstance(sensor, Radar):
        return _physics_view(_radar_terms, scene, params_of(RadarParams, r), sensor.config, noise, mode,
                             temperature, weather)
    if isinstance(sensor, Camera):
        return _physics_view(_camera_terms, scene, params_of(CameraParams, r), sensor.config, noise, mode,
                             temperature, weather)
    covariance = getattr(sensor, "measurement_covariance", None)
    if covariance is None:
        raise InputError(f"sensor {sensor.kind!r} cannot be fused: it defines no "
                         "measurement_covariance(scene, r, mode, temperature, weather)")
    return (sensor._detect(scene, r, noise, mode, temperature, weather),
            covariance(scene, r, mode, temperature, weather))
