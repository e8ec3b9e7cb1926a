"""Where each vehicle is as seen from a sensor mounted on the ego, and back to the world.

The sensor sits at its `Mount` on the ego (x ahead of the ego's reference point, y to its left,
boresight turned by the yaw; a bare number is `mount_x_m` on the centre line, facing forward).
Polar coordinates in the sensor frame: range [m] and azimuth [rad] (counter-clockwise from the
boresight, in [-pi, pi]). Every norm, angle and division is safe at zero (a vehicle
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
from diffsense.sensors._gates import Mode, soft_less, soft_ramp
from diffsense.sensors._mount import Mount, as_mount, is_static_zero


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


def sensor_pose(tracks: Tracks, mount: Mount | float):
    """World position and boresight yaw of the sensor per frame: (x_m [T], y_m [T], yaw_rad [T])."""
    mount = as_mount(mount)
    heading = tracks.heading_rad[EGO_INDEX]
    c, s = jnp.cos(heading), jnp.sin(heading)
    x = tracks.x_m[EGO_INDEX] + mount.x_m * c
    y = tracks.y_m[EGO_INDEX] + mount.x_m * s
    # A static zero offset or yaw is skipped, not added: a default mounting then compiles to the
    # program (and numbers) of the forward-facing centre-line sensor, bit for bit.
    if not is_static_zero(mount.y_m):
        x, y = x - mount.y_m * s, y + mount.y_m * c
    yaw = heading if is_static_zero(mount.yaw_rad) else heading + mount.yaw_rad
    return x, y, yaw


def safe_norm(a: Float[Array, "..."], b: Float[Array, "..."]) -> Float[Array, "..."]:
    """sqrt(a^2 + b^2) with a zero (not NaN) gradient at the origin."""
    sq = a * a + b * b
    ok = sq > 0
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, sq, 1.0)), 0.0)


# atan(a) ~ a P(a^2) on [0, 1]: a minimax fit (Lawson-weighted least squares, degree 8 in a^2),
# |error| < 6e-9 rad. XLA's CPU atan2 is a scalar library call, ~5x slower than this polynomial,
# and the sensor takes two per vehicle and frame.
_ATAN_COEFFS = (0.9999998863917418, -0.3333259705284096, 0.19985906992481606,
                -0.14161230150328755, 0.10498948192220618, -0.0723485986417579,
                0.0397812378982508, -0.014401360357972614, 0.0024567240478806924)


def safe_atan2(y: Float[Array, "..."], x: Float[Array, "..."]) -> Float[Array, "..."]:
    """atan2(y, x) in [-pi, pi] to 6e-9 rad; 0 with a zero gradient at (0, 0)."""
    ax, ay = jnp.abs(x), jnp.abs(y)
    steep = ay > ax  # (where, not max/min: those split the gradient at ax == ay)
    big, small = jnp.where(steep, ay, ax), jnp.where(steep, ax, ay)
    ok = big > 0
    a = jnp.where(ok, small / jnp.where(ok, big, 1.0), 0.0)
    s = a * a
    poly = _ATAN_COEFFS[-1]
    for c in _ATAN_COEFFS[-2::-1]:
        poly = poly * s + c
    r = a * poly
    r = jnp.where(steep, 0.5 * jnp.pi - r, r)
    r = jnp.where(x < 0, jnp.pi - r, r)
    return jnp.where(y < 0, -r, r)


def wrap_angle(a: Float[Array, "..."]) -> Float[Array, "..."]:
    """Angle wrapped to [-pi, pi] [rad] (by rounding: several times cheaper than `mod` on CPU)."""
    return a - (2 * jnp.pi) * jnp.round(a / (2 * jnp.pi))


def polar(tracks: Tracks, mount: Mount | float):
    """Range [m] and azimuth [rad] of every vehicle centre from the sensor, each [V, T]."""
    sx, sy, yaw = sensor_pose(tracks, mount)
    dx = tracks.x_m - sx
    dy = tracks.y_m - sy
    c, s = jnp.cos(yaw), jnp.sin(yaw)
    forward = c * dx + s * dy
    left = -s * dx + c * dy
    return safe_norm(forward, left), safe_atan2(left, forward)


def to_world(tracks: Tracks, mount: Mount | float, range_m, azimuth_error_rad):
    """World (x_m, y_m) [V, T] of a measured range along each vehicle's line of sight, turned
    by the azimuth error, with the ego's own pose.

    The turn is the Cayley rotation of the error e (cos, sin = (1 - q^2, 2 q) / (1 + q^2), q = e/2):
    an exact rotation by 2 atan(e / 2) = e - e^3 / 12 + ..., without trigonometric calls.
    """
    sx, sy, yaw = sensor_pose(tracks, mount)
    dx = tracks.x_m - sx
    dy = tracks.y_m - sy
    r = safe_norm(dx, dy)
    ok = r > 0
    inv_r = 1.0 / jnp.where(ok, r, 1.0)
    ux = jnp.where(ok, dx * inv_r, jnp.cos(yaw))  # co-located: straight ahead (azimuth 0)
    uy = jnp.where(ok, dy * inv_r, jnp.sin(yaw))
    q = 0.5 * azimuth_error_rad
    norm = 1.0 / (1.0 + q * q)
    cos_e, sin_e = (1.0 - q * q) * norm, 2.0 * q * norm
    return (sx + range_m * (cos_e * ux - sin_e * uy), sy + range_m * (sin_e * ux + cos_e * uy))


def angular_half_width(tracks: Tracks, range_m, azimuth_rad, mount: Mount | float):
    """Half the angle [rad] a vehicle's footprint subtends at the sensor, [V, T].

    The footprint's extent across the line of sight is |L sin(rel)| + |W cos(rel)| with rel the
    body yaw relative to the line of sight; the angle stays finite (pi/2) at zero range.
    """
    _, _, yaw = sensor_pose(tracks, mount)
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


def vehicle_occlusion(tracks: Tracks, range_m, azimuth_rad, mount: Mount | float, mode: Mode,
                      tau_near_m, tau_overlap_deg):
    """Angular half-width [rad] and occluded fraction of every vehicle, each [V, T].

    Occluders are the present vehicles other than the ego.
    """
    half = angular_half_width(tracks, range_m, azimuth_rad, mount)
    occluder = tracks.present & (jnp.arange(tracks.x_m.shape[0]) != EGO_INDEX)[:, None]
    return half, occluded_fraction(range_m, azimuth_rad, half, occluder, mode, tau_near_m,
                                   jnp.deg2rad(tau_overlap_deg))
