"""Where each vehicle is as seen from a sensor mounted on the ego, and back to the world.

The sensor sits `mount_x_m` ahead of the ego reference point along the ego heading and faces
forward. Polar coordinates in the sensor frame: range [m] and azimuth [rad] (counter-clockwise,
0 = straight ahead, in [-pi, pi]). Every norm, angle and division is safe at zero (a vehicle
co-located with the sensor, padding of zero size), so gradients stay finite.

The models work vehicle-major, arrays [V, T] (pairs [V, V, T]): time is the long minor axis, which
XLA's CPU backend vectorises; with the scene's [T, V] layout the minor axis is the handful of
vehicles and the transcendental functions run several times slower.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from diffsense.scene import EGO_INDEX, Scene
from diffsense.sensor._gates import Mode, soft_less, soft_ramp


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Tracks:
    """One scene, vehicle-major: per-frame arrays [V, T], per-vehicle arrays [V, 1]."""

    x_m: Float[Array, "V T"]
    y_m: Float[Array, "V T"]
    heading_rad: Float[Array, "V T"]
    length_m: Float[Array, "V 1"]
    width_m: Float[Array, "V 1"]
    kind: Int[Array, "V 1"]
    present: Bool[Array, "V 1"]

    @classmethod
    def of(cls, scene: Scene) -> Tracks:
        """The vehicle-major view of one scene [T, V]."""
        return cls(x_m=scene.x_m.T, y_m=scene.y_m.T, heading_rad=scene.heading_rad.T,
                   length_m=scene.length_m[:, None], width_m=scene.width_m[:, None],
                   kind=scene.kind[:, None], present=scene.present[:, None] != 0)


def sensor_pose(tracks: Tracks, mount_x_m: float):
    """World position and yaw of the sensor per frame: (x_m [T], y_m [T], yaw_rad [T])."""
    yaw = tracks.heading_rad[EGO_INDEX]
    x = tracks.x_m[EGO_INDEX] + mount_x_m * jnp.cos(yaw)
    y = tracks.y_m[EGO_INDEX] + mount_x_m * jnp.sin(yaw)
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
    """Angle wrapped to [-pi, pi] [rad] (by rounding: several times cheaper than `mod` on CPU)."""
    return a - (2 * jnp.pi) * jnp.round(a / (2 * jnp.pi))


def polar(tracks: Tracks, mount_x_m: float):
    """Range [m] and azimuth [rad] of every vehicle centre from the sensor, each [V, T]."""
    sx, sy, yaw = sensor_pose(tracks, mount_x_m)
    dx = tracks.x_m - sx
    dy = tracks.y_m - sy
    c, s = jnp.cos(yaw), jnp.sin(yaw)
    forward = c * dx + s * dy
    left = -s * dx + c * dy
    return safe_norm(forward, left), safe_atan2(left, forward)


def to_world(tracks: Tracks, mount_x_m: float, range_m, azimuth_rad):
    """World (x_m, y_m) [V, T] of sensor-frame polar measurements, with the ego's own pose."""
    sx, sy, yaw = sensor_pose(tracks, mount_x_m)
    bearing = yaw + azimuth_rad
    return sx + range_m * jnp.cos(bearing), sy + range_m * jnp.sin(bearing)


def angular_half_width(tracks: Tracks, range_m, azimuth_rad, mount_x_m: float):
    """Half the angle [rad] a vehicle's footprint subtends at the sensor, [V, T].

    The footprint's extent across the line of sight is |L sin(rel)| + |W cos(rel)| with rel the
    body yaw relative to the line of sight; the angle stays finite (pi/2) at zero range.
    """
    _, _, yaw = sensor_pose(tracks, mount_x_m)
    rel = tracks.heading_rad - (yaw + azimuth_rad)
    across = jnp.abs(tracks.length_m * jnp.sin(rel)) + jnp.abs(tracks.width_m * jnp.cos(rel))
    return safe_atan2(0.5 * across, range_m)


def occluded_fraction(
    range_m: Float[Array, "V T"],
    azimuth_rad: Float[Array, "V T"],
    half_width_rad: Float[Array, "V T"],
    occluder: Bool[Array, "V 1"],
    mode: Mode,
    tau_near_m,
    tau_overlap_rad,
) -> Float[Array, "V T"]:
    """Fraction of each vehicle's angular interval covered by nearer vehicles, in [0, 1].

    Vehicle j is covered by every occluder i != j that is nearer (soft: sigmoid of the range gap)
    by the overlap of their angular intervals (soft: smoothed clip). Overlaps are summed (an
    upper bound of the union) and capped at 1. Cost O(V^2 T), as a scan over occluders i of
    [V, T] steps: ten times faster on CPU than materialising the [V, V, T] pairs.
    """
    index = jnp.arange(range_m.shape[0])[:, None]

    def add_occluder(covered, i):
        gap = wrap_angle(azimuth_rad - azimuth_rad[i])
        hi = half_width_rad[i]
        overlap = soft_ramp(hi + half_width_rad - jnp.abs(gap),
                            2.0 * jnp.minimum(hi, half_width_rad), tau_overlap_rad, mode)
        nearer = soft_less(range_m[i], range_m, tau_near_m, mode)
        counts = (occluder[i] & (index != i)).astype(range_m.dtype)
        return covered + counts * nearer * overlap, None

    covered, _ = jax.lax.scan(add_occluder, jnp.zeros_like(range_m), jnp.arange(range_m.shape[0]))
    width = 2.0 * half_width_rad
    ok = width > 0
    frac = jnp.where(ok, covered / jnp.where(ok, width, 1.0), 0.0)
    return jnp.minimum(frac, 1.0)


def vehicle_occlusion(tracks: Tracks, range_m, azimuth_rad, mount_x_m: float, mode: Mode,
                      tau_near_m, tau_overlap_deg):
    """Angular half-width [rad] and occluded fraction of every vehicle, each [V, T].

    Occluders are the present vehicles other than the ego.
    """
    half = angular_half_width(tracks, range_m, azimuth_rad, mount_x_m)
    occluder = tracks.present & (jnp.arange(tracks.x_m.shape[0]) != EGO_INDEX)[:, None]
    return half, occluded_fraction(range_m, azimuth_rad, half, occluder, mode, tau_near_m,
                                   jnp.deg2rad(tau_overlap_deg))
