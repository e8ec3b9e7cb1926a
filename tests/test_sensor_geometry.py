"""The sensors' geometry and gates against numpy written independently: the fast atan2 and norm
(safe at zero), angle wrapping, the sensor frame from its mounting and back to the world, the
footprint's angular width from its corners, occlusion, the gates (softplus, logistic product,
hard edges, ramps), and soft detection converging to hard as the temperature shrinks.
`_geometry` and `_gates` are the physics under test here.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _laws import threshold_config
from _sensor_scenes import jit_p_detect, make_scene

from diffsense import sensors
from diffsense.scene import CAR, TRUCK
from diffsense.sensors import _gates as gates
from diffsense.sensors import _geometry as geo
from diffsense.sensors._camera import _camera_terms
from diffsense.sensors._radar import _radar_terms

polar = jax.jit(geo.polar, static_argnums=1)
to_world = jax.jit(geo.to_world, static_argnums=1)
sensor_pose = jax.jit(geo.sensor_pose, static_argnums=1)
half_width = jax.jit(geo.angular_half_width, static_argnums=3)
occluded_fraction = jax.jit(geo.occluded_fraction, static_argnums=4)


def test_the_fast_atan2_matches_numpy_in_every_octant():
    a = np.linspace(-math.pi, math.pi, 2001)
    r = np.array([1e-3, 1.0, 250.0])[:, None]
    y, x = r * np.sin(a), r * np.cos(a)
    x[:, [0, -1]] = -r  # exactly on the negative x axis: +pi from above
    y[:, [0, -1]] = 0.0
    np.testing.assert_allclose(np.asarray(geo.safe_atan2(jnp.asarray(y), jnp.asarray(x))), np.arctan2(y, x),
                               atol=6e-9, rtol=0)
    for yy, xx in [(1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (-1.0, -1.0), (2.0, -2.0)]:
        assert float(geo.safe_atan2(yy, xx)) == pytest.approx(math.atan2(yy, xx), abs=6e-9)


def test_atan2_and_norm_are_zero_with_zero_gradient_at_the_origin():
    assert float(geo.safe_atan2(0.0, 0.0)) == 0.0 and float(geo.safe_norm(0.0, 0.0)) == 0.0
    for fn in (geo.safe_atan2, geo.safe_norm):
        np.testing.assert_array_equal(np.asarray(jax.grad(lambda v, fn=fn: fn(v[0], v[1]))(jnp.zeros(2))), [0.0, 0.0])
    norm_grad = jax.grad(lambda v: geo.safe_norm(v[0], v[1]))
    # away from it: d|v|/dv = v / |v|; d atan2(y, x)/d(y, x) = (x, -y) / |v|^2 (to the polynomial's slope)
    np.testing.assert_allclose(norm_grad(jnp.array([3.0, 4.0])), [0.6, 0.8], rtol=1e-12)
    np.testing.assert_allclose(jax.grad(lambda v: geo.safe_atan2(v[0], v[1]))(jnp.array([3.0, 4.0])),
                               [4 / 25, -3 / 25], rtol=1e-6)
    assert float(geo.safe_norm(-3.0, 4.0)) == 5.0
    assert float(geo.safe_norm(0.3, -0.4)) == pytest.approx(0.5, rel=1e-12)  # below a metre, not the origin's 0
    np.testing.assert_allclose(norm_grad(jnp.array([0.3, -0.4])), [0.6, -0.8], rtol=1e-12)


def test_wrap_angle():
    a = np.array([1.5 * np.pi, -1.5 * np.pi, 7.0, -7.0, 0.3, 3.0])
    want = np.array([-0.5 * np.pi, 0.5 * np.pi, 7.0 - 2 * np.pi, 2 * np.pi - 7.0, 0.3, 3.0])
    np.testing.assert_allclose(np.asarray(geo.wrap_angle(jnp.asarray(a))), want, atol=1e-12)


def _posed_scene():
    # Ego at (5, -2) heading 30 deg; targets at sensor-frame (forward, left) = (40, 3), (10, -25).
    yaw, mount = math.radians(30.0), 2.5
    c, s = math.cos(yaw), math.sin(yaw)
    sx, sy = 5.0 + mount * c, -2.0 + mount * s
    rel = np.array([[40.0, 3.0], [10.0, -25.0]])
    x = np.r_[5.0, sx + c * rel[:, 0] - s * rel[:, 1]]
    y = np.r_[-2.0, sy + s * rel[:, 0] + c * rel[:, 1]]
    heading = np.array([yaw, yaw + 0.5, yaw - 1.0])
    return make_scene(x[None], y[None], heading_rad=heading[None], length_m=[4.5, 4.5, 12.0],
                      width_m=[1.8, 1.8, 2.5]), rel, mount


def test_polar_and_back_to_the_world_with_an_azimuth_error():
    scene, rel, mount = _posed_scene()
    tracks = geo.Tracks.of(scene)
    r, az = (np.asarray(v)[1:, 0] for v in polar(tracks, mount))
    np.testing.assert_allclose(r, np.hypot(rel[:, 0], rel[:, 1]), rtol=1e-12)
    np.testing.assert_allclose(az, np.arctan2(rel[:, 1], rel[:, 0]), atol=1e-8)
    # Measured 1 m long and turned by e = 0.2 rad: the line of sight rotated by 2 atan(0.1).
    x, y = to_world(tracks, mount, jnp.zeros((3, 1)).at[1:, 0].set(r + 1.0), jnp.full((3, 1), 0.2))
    sx, sy, yaw = (float(v[0]) for v in sensor_pose(tracks, mount))
    turn = yaw + np.arctan2(rel[:, 1], rel[:, 0]) + 2 * np.arctan(0.1)
    np.testing.assert_allclose(np.asarray(x)[1:, 0], sx + (r + 1.0) * np.cos(turn), atol=1e-9)
    np.testing.assert_allclose(np.asarray(y)[1:, 0], sy + (r + 1.0) * np.sin(turn), atol=1e-9)


@pytest.mark.parametrize("heading_rad", [0.0, 0.5])
def test_range_and_azimuth_are_measured_from_the_mount_point_and_the_yaw(heading_rad):
    # Mount 3 m ahead, 0.6 m left, boresight 20 deg left; one car 20 m along the boresight, one 10 m
    # along a line 25 deg right of the ego's heading (45 deg right of the boresight); then the
    # scene turned by the ego's heading: ranges 20 and 10 m, azimuths 0 and -45 deg whatever it is.
    sx, sy = 3.0, 0.6
    local = [(0.0, 0.0), (sx + 20 * math.cos(math.radians(20)), sy + 20 * math.sin(math.radians(20))),
             (sx + 10 * math.cos(math.radians(-25)), sy + 10 * math.sin(math.radians(-25)))]
    c, s = math.cos(heading_rad), math.sin(heading_rad)
    scene = make_scene([[c * u - s * v for u, v in local]], [[s * u + c * v for u, v in local]], heading_rad=heading_rad)
    range_m, azimuth_rad = polar(geo.Tracks.of(scene), sensors.Mount(x_m=sx, y_m=sy, yaw_rad=math.radians(20)))
    np.testing.assert_allclose(np.asarray(range_m)[1:, 0], [20.0, 10.0], rtol=1e-12)
    np.testing.assert_allclose(np.degrees(np.asarray(azimuth_rad)[1:, 0]), [0.0, -45.0], atol=1e-6)


def test_the_angular_half_width_from_the_footprints_corners():
    scene, rel, mount = _posed_scene()
    tracks = geo.Tracks.of(scene)
    r, az = polar(tracks, mount)
    got = np.asarray(half_width(tracks, r, az, mount))[1:, 0]
    want = []
    for k, (lon, lat) in enumerate(rel, start=1):
        rel_heading = float(scene.heading_rad[0, k] - scene.heading_rad[0, 0])
        half_l, half_w = float(scene.length_m[k]) / 2, float(scene.width_m[k]) / 2
        c, s = math.cos(rel_heading), math.sin(rel_heading)
        corners = np.array([[c * a - s * b, s * a + c * b] for a in (-half_l, half_l) for b in (-half_w, half_w)])
        proj = corners @ (np.array([-lat, lon]) / math.hypot(lon, lat))  # across the ray
        want.append(math.atan(0.5 * (proj.max() - proj.min()) / math.hypot(lon, lat)))
    np.testing.assert_allclose(got, want, atol=6e-9, rtol=0)  # the fast atan's error bound


# Target 0 at 50 m spans [-0.1, 0.1] rad; occluders 1 and 2 (20 m) span [-0.14, 0.04] and
# [-0.04, 0.14]: each covers 70 %, summed 140 %, capped at 1. Vehicle 3 (80 m, [-0.5, 0.5]) is
# farthest: covered by 0 (its whole 0.2 rad) and 1 (0.18 rad).
R = jnp.array([[50.0], [20.0], [20.0], [80.0]])
AZ = jnp.array([[0.0], [-0.05], [0.05], [0.0]])
HALF = jnp.array([[0.1], [0.09], [0.09], [0.5]])


def test_occluded_fraction_sums_overlaps_and_caps_at_one():
    occ = jnp.ones((4, 1), bool)
    both = np.asarray(occluded_fraction(R, AZ, HALF, occ, "hard", 1.0, 0.01))[:, 0]
    assert both[0] == 1.0 and both[1] == 0.0  # 1 and 2 at equal range do not hide each other
    one = np.asarray(occluded_fraction(R, AZ, HALF, occ.at[2].set(False), "hard", 1.0, 0.01))
    assert float(one[0, 0]) == pytest.approx(0.7, abs=1e-12)
    assert float(one[3, 0]) == pytest.approx(0.38, abs=1e-12)


@pytest.mark.parametrize("turn", [0.2, math.pi - 0.02, -2.5])
def test_occluded_fraction_depends_on_azimuth_differences_only(turn):
    # Turned by pi - 0.02, occluder 2 lands at -pi + 0.03 and the car it covers at pi - 0.02.
    occ = jnp.array([[True], [False], [True], [True]])
    base = np.asarray(occluded_fraction(R, AZ, HALF, occ, "hard", 1.0, 0.01))
    turned = np.asarray(occluded_fraction(R, geo.wrap_angle(AZ + turn), HALF, occ, "hard", 1.0, 0.01))
    np.testing.assert_allclose(turned, base, atol=1e-12)
    np.testing.assert_allclose(base[:, 0], [0.7, 0.0, 0.0, 0.38], atol=1e-12)


def test_a_zero_width_vehicle_is_not_occluded_and_has_a_finite_gradient():
    def frac(h0):
        half = jnp.array([[0.0], [0.1]]).at[0, 0].set(h0)
        return occluded_fraction(jnp.array([[50.0], [20.0]]), jnp.zeros((2, 1)), half, jnp.ones((2, 1), bool),
                                 "soft", 1.0, 0.01)[0, 0]

    assert float(frac(0.0)) == 0.0 and np.isfinite(float(jax.grad(frac)(0.0)))


def test_occlusion_is_seen_from_the_mount_point():
    # Camera 2.5 m ahead; an occluder (4.5 x 1.8 m) at (12, 1.6) and the target at (40, 3.0). By hand:
    #   from (2.5, 0):    occluder 9.560 +- 7.458 deg = [2.102, 17.018], target [2.935, 6.213]: covered whole;
    #   from (2.5, -0.9): occluder [6.387, 23.100], target [4.224, 7.651]: covered 1.264 of 3.427 deg = 0.36879,
    #                     detected (>= 0.6 visible).
    camera = sensors.Camera(threshold_config("camera"))
    scene = make_scene([[0.0, 40.0, 12.0]], [[0.0, 3.0, 1.6]])
    tracks = geo.Tracks.of(scene)
    for y_m, hidden, seen in [(0.0, 1.0, 0.0), (-0.9, 0.36879, 1.0)]:
        mount = sensors.Mount(x_m=2.5, y_m=y_m)
        range_m, azimuth_rad = polar(tracks, mount)
        _, fraction = geo.vehicle_occlusion(tracks, range_m, azimuth_rad, mount, "hard", 1.0, 0.2)
        assert float(fraction[1, 0]) == pytest.approx(hidden, abs=2e-5)
        det = camera.detect(scene, {"hfov_deg": 90.0, "mount_y_m": y_m}, jax.random.key(5), mode="hard")
        assert float(det.p_detect[0, 1]) == seen


@pytest.mark.parametrize("name", ["radar", "camera"])
def test_hard_mode_compares_ranges_hard(name):
    # An occluder only 0.5 m nearer than the car it covers by 45 %: hard "nearer" is 1 (the camera
    # misses the car), where a soft comparison (sigmoid(0.5 / 1 m) = 0.62) would count 28 %.
    config = threshold_config(name)
    s0 = config.mount_x_m + 30.0
    scene = make_scene([[0.0, s0 - 0.5, s0]], [[0.0, 1.8 * 0.55, 0.0]])
    params = sensors.make_params(config, hfov_deg=60.0)
    hard = np.asarray(jit_p_detect(scene, params, config, mode="hard"))
    det = sensors.detect(scene, params, config, jax.random.key(2, impl="rbg"), mode="hard")
    np.testing.assert_array_equal(np.asarray(det.p_detect), hard)
    assert hard[0, 2] == (1.0 if name == "radar" else 0.0)


def test_softplus_and_log_sigmoid_match_logaddexp():
    z = np.linspace(-60.0, 60.0, 241)
    np.testing.assert_allclose(np.asarray(gates.softplus(jnp.asarray(z))), np.logaddexp(0.0, z), atol=1e-12, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(gates.log_sigmoid(jnp.asarray(z))), -np.logaddexp(0.0, -z), atol=1e-12,
                               rtol=1e-12)
    assert float(gates.exp_log_p(-100.0)) == pytest.approx(math.exp(-80.0), rel=1e-12)  # floored at e^-80
    assert float(gates.exp_log_p(-2.0)) == pytest.approx(math.exp(-2.0), rel=1e-12)


def test_the_gate_product_soft_and_hard_and_the_ramps():
    margins = [(jnp.array([3.0, -1.0, 0.0]), 2.0), (jnp.array([0.5, 4.0, 2.0]), 0.25)]
    sig = lambda v: 1.0 / (1.0 + np.exp(-v))  # noqa: E731
    np.testing.assert_allclose(np.asarray(gates.p_from_gates(margins, "soft")),
                               sig(np.array([3.0, -1.0, 0.0]) / 2.0) * sig(np.array([0.5, 4.0, 2.0]) / 0.25), rtol=1e-12)
    np.testing.assert_array_equal(np.asarray(gates.p_from_gates(margins, "hard")), [1.0, 0.0, 1.0])  # 0 passes
    x = jnp.array([-1.0, 0.0, 0.3, 1.0, 2.0])
    np.testing.assert_array_equal(np.asarray(gates.soft_ramp(x, 1.0, 0.1, "hard")), [0, 0, 0.3, 1, 1])
    soft = np.asarray(gates.soft_ramp(x, 1.0, 0.1, "soft"))
    relu = lambda z: 0.5 * (z + np.sqrt(z * z + 0.01))  # noqa: E731
    np.testing.assert_allclose(soft, relu(np.asarray(x)) - relu(np.asarray(x) - 1.0), rtol=1e-12)
    assert np.all(np.abs(soft - np.clip(np.asarray(x), 0, 1)) <= 0.05 + 1e-12)  # within tau / 2
    a, b = jnp.array([1.0, 2.0, 3.0]), jnp.array([2.0, 2.0, 2.0])
    np.testing.assert_array_equal(np.asarray(gates.soft_less(a, b, 0.5, "hard")), [1, 0, 0])
    np.testing.assert_allclose(np.asarray(gates.soft_less(a, b, 0.5, "soft")),
                               1 / (1 + np.exp(-(np.asarray(b) - np.asarray(a)) / 0.5)), rtol=1e-12)


# Soft -> hard: as the temperature shrinks, soft p converges to the hard detection everywhere but
# within a few temperatures of an edge (a gate's, or an occlusion comparison's).
EDGE = 8.0  # a gate at 8 tau is within sigmoid(-8) = 3.4e-4 of its indicator
SOFT_HARD = {
    "radar": (_radar_terms, sensors.make_params(threshold_config("radar"), hfov_deg=60.0)),
    "camera": (_camera_terms, sensors.make_params(threshold_config("camera"), hfov_deg=150.0)),
}


@functools.lru_cache
def probe_grid():
    """One probe car at each point of a grid around the ego, with two fixed occluders."""
    gx, gy = np.meshgrid(np.linspace(-20.0, 140.0, 41), np.linspace(-70.0, 70.0, 29))
    g = gx.size
    x = np.stack([np.zeros(g), gx.ravel(), np.full(g, 25.0), np.full(g, 60.0)], axis=1)
    y = np.stack([np.zeros(g), gy.ravel(), np.full(g, 1.0), np.full(g, -8.0)], axis=1)
    return make_scene(x, y, length_m=[4.5, 4.5, 12.0, 4.5], width_m=[1.8, 1.8, 2.5, 1.8], kind=[CAR, CAR, TRUCK, CAR])


def occlusion_edge_distance(scene, config):
    """Per (frame, vehicle): distance, in temperatures, to the nearest occlusion comparison edge
    (equal ranges of two overlapping vehicles, and the two kinks of the overlap clip)."""
    tau, tracks = config.temperature, geo.Tracks.of(scene)
    r, az = polar(tracks, config.mount_x_m)
    half = half_width(tracks, r, az, config.mount_x_m).T
    r, az = r.T, az.T  # [T, V]
    hi, hj = half[:, :, None], half[:, None, :]
    reach = hi + hj - jnp.abs(geo.wrap_angle(az[:, None, :] - az[:, :, None]))
    ov_tau = jnp.deg2rad(tau.overlap_deg)
    near = jnp.abs(r[:, None, :] - r[:, :, None]) / tau.near_m
    kinks = jnp.minimum(jnp.abs(reach), jnp.abs(reach - 2 * jnp.minimum(hi, hj))) / ov_tau
    dist = jnp.minimum(kinks, jnp.where(reach > -EDGE * ov_tau, near, jnp.inf))
    v = r.shape[-1]
    occluder = (jnp.arange(v) > 0)[:, None] & ~jnp.eye(v, dtype=bool)
    return jnp.min(jnp.where(occluder, dist, jnp.inf), axis=1)


@functools.partial(jax.jit, static_argnames=("name",))
def soft_hard_and_edge(scene, params, temperature, *, name):
    terms, _ = SOFT_HARD[name]
    config = threshold_config(name)
    soft = sensors.p_detect(scene, params, config, mode="soft", temperature=temperature)
    hard = sensors.p_detect(scene, params, config, mode="hard")
    edge = jnp.min(jnp.stack([jnp.abs(m).T / (t * temperature)
                              for m, t in terms(geo.Tracks.of(scene), params, config, "hard", 1.0)[0]]), axis=0)
    edge = jnp.minimum(edge, occlusion_edge_distance(scene, config) / temperature)
    return soft[:, 1:], hard[:, 1:], edge[:, 1:]


@pytest.mark.parametrize("name", ["radar", "camera"])
def test_soft_converges_to_hard_away_from_edges(name):
    errors, near_edge = [], []
    for temperature in (1.0, 0.1, 0.01, 0.001):
        soft, hard, edge = map(np.asarray, soft_hard_and_edge(probe_grid(), SOFT_HARD[name][1], temperature, name=name))
        away = edge > EDGE
        assert np.max(np.abs(soft - hard)[away]) < 5e-3, temperature
        errors.append(np.mean(np.abs(soft - hard)))
        near_edge.append(np.mean(~away))
    assert all(a > b for a, b in zip(errors, errors[1:])), errors
    assert near_edge[-1] < 0.01 and errors[-1] < 0.01, (near_edge, errors)
    assert 0.05 < np.mean(hard) < 0.95  # both detected and missed probes exist
