"""Where each vehicle is as seen from a sensor mounted on the ego, and back to the world.

The sensor sits `mount_x_m` ahead of the ego reference point along the ego heading and faces
forward. Polar coordinates in the sensor frame: range [m] and azimuth [rad] (counter-clockwise,
0 = straight ahead, in (-pi, pi]). Every norm, angle and division is safe at zero (a vehicle
co-located with the sensor, padding of zero size), so gradients stay finite.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from diffsense.scene import EGO_INDEX, Scene
from diffsense.sensor._gates import Mode, soft_less, soft_ramp


def sensor_pose(scene: Scene, mount_x_m: float):
    """World position and yaw of the sensor per frame: (x_m [T], y_m [T], yaw_rad [T])."""
    yaw = scene.heading_rad[..., EGO_INDEX]
    x = scene.x_m[..., EGO_INDEX] + mount_x_m * jnp.cos(yaw)
    y = scene.y_m[..., EGO_INDEX] + mount_x_m * jnp.sin(yaw)
    return x, y, yaw


def safe_norm(a: Float[Array, "..."], b: Float[Array, "..."]) -> Float[Array, "..."]:
    """sqrt(a^2 + b^2) with a zero (not NaN) gradient at the origin."""
    sq = a * a + b * b
    ok = sq > 0
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, sq, 1.0)), 0.0)


def safe_atan2(y: Float[Array, "..."], x: Float[Array, "..."]) -> Float[Array, "..."]:
    """atan2(y, x), 0 with a zero gradient at (0, 0)."""
    ok = (x != 0) | (y != 0)
    return jnp.where(ok, jnp.arctan2(jnp.where(ok, y, 0.0), jnp.where(ok, x, 1.0)), 0.0)


def wrap_angle(a: Float[Array, "..."]) -> Float[Array, "..."]:
    """Angle wrapped to [-pi, pi) [rad]."""
    return jnp.mod(a + jnp.pi, 2 * jnp.pi) - jnp.pi


def polar(scene: Scene, mount_x_m: float):
    """Range [m] and azimuth [rad] of every vehicle centre from the sensor, each [T, V]."""
    sx, sy, yaw = sensor_pose(scene, mount_x_m)
    dx = scene.x_m - sx[..., None]
    dy = scene.y_m - sy[..., None]
    c, s = jnp.cos(yaw)[..., None], jnp.sin(yaw)[..., None]
    forward = c * dx + s * dy
    left = -s * dx + c * dy
    return safe_norm(forward, left), safe_atan2(left, forward)


def to_world(scene: Scene, mount_x_m: float, range_m, azimuth_rad):
    """World (x_m, y_m) [T, V] of sensor-frame polar measurements, with the ego's own pose."""
    sx, sy, yaw = sensor_pose(scene, mount_x_m)
    bearing = yaw[..., None] + azimuth_rad
    return sx[..., None] + range_m * jnp.cos(bearing), sy[..., None] + range_m * jnp.sin(bearing)


def angular_half_width(scene: Scene, range_m, azimuth_rad, mount_x_m: float):
    """Half the angle [rad] a vehicle's footprint subtends at the sensor, [T, V].

    The footprint's extent across the line of sight is |L sin(rel)| + |W cos(rel)| with rel the
    body yaw relative to the line of sight; the angle stays finite (pi) at zero range.
    """
    _, _, yaw = sensor_pose(scene, mount_x_m)
    rel = scene.heading_rad - (yaw[..., None] + azimuth_rad)
    across = (jnp.abs(scene.length_m[..., None, :] * jnp.sin(rel))
              + jnp.abs(scene.width_m[..., None, :] * jnp.cos(rel)))
    return safe_atan2(0.5 * across, range_m)


def occluded_fraction(
    range_m: Float[Array, "T V"],
    azimuth_rad: Float[Array, "T V"],
    half_width_rad: Float[Array, "T V"],
    occluder: Bool[Array, "V"],
    mode: Mode,
    tau_near_m,
    tau_overlap_rad,
) -> Float[Array, "T V"]:
    """Fraction of each vehicle's angular interval covered by nearer vehicles, in [0, 1].

    Vehicle j is covered by every occluder i != j that is nearer (soft: sigmoid of the range gap)
    by the overlap of their angular intervals (soft: softplus-smoothed clip). Overlaps are
    summed (an upper bound of the union) and capped at 1. Cost O(T V^2).
    """
    gap = wrap_angle(azimuth_rad[..., None, :] - azimuth_rad[..., :, None])  # [T, i, j]
    hi, hj = half_width_rad[..., :, None], half_width_rad[..., None, :]
    cap = 2.0 * jnp.minimum(hi, hj)
    overlap = soft_ramp(hi + hj - jnp.abs(gap), cap, tau_overlap_rad, mode)
    nearer = soft_less(range_m[..., :, None], range_m[..., None, :], tau_near_m, mode)
    v = occluder.shape[-1]
    mask = (occluder[..., :, None] & ~jnp.eye(v, dtype=bool)).astype(range_m.dtype)
    covered = jnp.sum(mask * nearer * overlap, axis=-2)
    width = 2.0 * half_width_rad
    ok = width > 0
    frac = jnp.where(ok, covered / jnp.where(ok, width, 1.0), 0.0)
    return jnp.minimum(frac, 1.0)


def vehicle_occlusion(scene: Scene, range_m, azimuth_rad, mount_x_m: float, mode: Mode,
                      tau_near_m, tau_overlap_deg):
    """Angular half-width [rad] and occluded fraction of every vehicle, each [T, V].

    Occluders are the present vehicles other than the ego.
    """
    half = angular_half_width(scene, range_m, azimuth_rad, mount_x_m)
    occluder = (scene.present != 0) & (jnp.arange(scene.x_m.shape[-1]) != EGO_INDEX)
    return half, occluded_fraction(range_m, azimuth_rad, half, occluder, mode, tau_near_m,
                                   jnp.deg2rad(tau_overlap_deg))
