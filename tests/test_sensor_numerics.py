"""The sensors' numerical building blocks against numpy written independently: the fast atan2
and norm (and their safe gradients at zero), angle wrapping, the sensor frame and back, the
footprint's angular width, and the gates (softplus, logistic product, hard edges, ramps)."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_sensor_scenes import make_scene

from diffsense.runtime._errors import InputError
from diffsense.sensors import _gates as gates
from diffsense.sensors import _geometry as geo
from diffsense.sensors._geometry import Tracks

# Compiled once: eager jax runs every primitive separately, far slower on the test machine.
polar = jax.jit(geo.polar, static_argnums=1)
to_world = jax.jit(geo.to_world, static_argnums=1)
sensor_pose = jax.jit(geo.sensor_pose, static_argnums=1)
half_width = jax.jit(geo.angular_half_width, static_argnums=3)
occluded_fraction = jax.jit(geo.occluded_fraction, static_argnums=4)


def test_fast_atan2_matches_numpy_in_every_octant():
    a = np.linspace(-math.pi, math.pi, 2001)
    r = np.array([1e-3, 1.0, 250.0])[:, None]
    y, x = r * np.sin(a), r * np.cos(a)
    x[:, [0, -1]] = -r  # exactly on the negative x axis: +pi from above
    y[:, [0, -1]] = [[0.0, 0.0]] * 3
    got = np.asarray(geo.safe_atan2(jnp.asarray(y), jnp.asarray(x)))
    np.testing.assert_allclose(got, np.arctan2(y, x), atol=6e-9, rtol=0)
    # the axes and diagonals exactly
    for yy, xx in [(1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (1.0, 1.0), (-1.0, -1.0), (2.0, -2.0)]:
        assert float(geo.safe_atan2(yy, xx)) == pytest.approx(math.atan2(yy, xx), abs=6e-9)


def test_atan2_and_norm_are_zero_with_zero_gradient_at_the_origin():
    assert float(geo.safe_atan2(0.0, 0.0)) == 0.0 and float(geo.safe_norm(0.0, 0.0)) == 0.0
    for fn in (geo.safe_atan2, geo.safe_norm):
        g = jax.grad(lambda v: fn(v[0], v[1]))(jnp.zeros(2))
        np.testing.assert_array_equal(np.asarray(g), [0.0, 0.0])
    # away from it: d|v|/dv = v / |v|; d atan2(y, x)/d(y, x) = (x, -y) / |v|^2
    np.testing.assert_allclose(jax.grad(lambda v: geo.safe_norm(v[0], v[1]))(jnp.array([3.0, 4.0])),
                               [0.6, 0.8], rtol=1e-12)
    np.testing.assert_allclose(jax.grad(lambda v: geo.safe_atan2(v[0], v[1]))(jnp.array([3.0, 4.0])),
                               [4 / 25, -3 / 25], rtol=1e-6)  # the polynomial's slope error
    assert float(geo.safe_norm(-3.0, 4.0)) == 5.0
    # below a metre too (a car beside the sensor): 0.5 m, not the origin's 0
    assert float(geo.safe_norm(0.3, -0.4)) == pytest.approx(0.5, rel=1e-12)
    np.testing.assert_allclose(jax.grad(lambda v: geo.safe_norm(v[0], v[1]))(jnp.array([0.3, -0.4])),
                               [0.6, -0.8], rtol=1e-12)


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
    tracks = Tracks.of(scene)
    r, az = (np.asarray(v)[1:, 0] for v in polar(tracks, mount))
    np.testing.assert_allclose(r, np.hypot(rel[:, 0], rel[:, 1]), rtol=1e-12)
    np.testing.assert_allclose(az, np.arctan2(rel[:, 1], rel[:, 0]), atol=1e-8)
    # Measured 1 m long and turned by e = 0.2 rad: the line of sight rotated by 2 atan(0.1).
    measured = jnp.zeros((3, 1)).at[1:, 0].set(r + 1.0)  # [V, T]
    x, y = to_world(tracks, mount, measured, jnp.full((3, 1), 0.2))
    sx, sy, yaw = (float(v[0]) for v in sensor_pose(tracks, mount))
    turn = yaw + np.arctan2(rel[:, 1], rel[:, 0]) + 2 * np.arctan(0.1)
    np.testing.assert_allclose(np.asarray(x)[1:, 0], sx + (r + 1.0) * np.cos(turn), atol=1e-9)
    np.testing.assert_allclose(np.asarray(y)[1:, 0], sy + (r + 1.0) * np.sin(turn), atol=1e-9)


def test_angular_half_width_from_the_footprint_corners():
    scene, rel, mount = _posed_scene()
    tracks = Tracks.of(scene)
    r, az = polar(tracks, mount)
    got = np.asarray(half_width(tracks, r, az, mount))[1:, 0]
    want = []
    for k, (lon, lat) in enumerate(rel, start=1):
        # footprint corners relative to the vehicle centre, in the sensor frame
        rel_heading = float(scene.heading_rad[0, k] - scene.heading_rad[0, 0])
        half_l, half_w = float(scene.length_m[k]) / 2, float(scene.width_m[k]) / 2
        c, s = math.cos(rel_heading), math.sin(rel_heading)
        corners = np.array([[c * a - s * b, s * a + c * b] for a in (-half_l, half_l)
                            for b in (-half_w, half_w)])
        across = np.array([-lat, lon]) / math.hypot(lon, lat)  # unit vector across the ray
        proj = corners @ across
        want.append(math.atan(0.5 * (proj.max() - proj.min()) / math.hypot(lon, lat)))
    np.testing.assert_allclose(got, want, atol=6e-9, rtol=0)  # the fast atan's error bound


def test_softplus_and_log_sigmoid_match_logaddexp():
    z = np.linspace(-60.0, 60.0, 241)
    np.testing.assert_allclose(np.asarray(gates.softplus(jnp.asarray(z))), np.logaddexp(0.0, z),
                               atol=1e-12, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(gates.log_sigmoid(jnp.asarray(z))), -np.logaddexp(0.0, -z),
                               atol=1e-12, rtol=1e-12)
    assert float(gates.exp_log_p(-100.0)) == pytest.approx(math.exp(-80.0), rel=1e-12)
    assert float(gates.exp_log_p(-2.0)) == pytest.approx(math.exp(-2.0), rel=1e-12)


def test_gate_product_soft_and_hard_edges():
    margins = [(jnp.array([3.0, -1.0, 0.0]), 2.0), (jnp.array([0.5, 4.0, 2.0]), 0.25)]
    soft = np.asarray(gates.p_from_gates(margins, "soft"))
    sig = lambda v: 1.0 / (1.0 + np.exp(-v))  # noqa: E731
    want = sig(np.array([3.0, -1.0, 0.0]) / 2.0) * sig(np.array([0.5, 4.0, 2.0]) / 0.25)
    np.testing.assert_allclose(soft, want, rtol=1e-12)
    hard = np.asarray(gates.p_from_gates(margins, "hard"))
    np.testing.assert_array_equal(hard, [1.0, 0.0, 1.0])  # a margin of exactly 0 passes


def test_soft_ramp_and_soft_less():
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


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf])
def test_a_bad_temperature_or_mode_is_one_clear_error(bad):
    with pytest.raises(InputError, match="temperature must be a positive number"):
        gates.check_temperature(bad)
    assert gates.check_temperature(0.5) == 0.5
    assert gates.check_mode("hard") == "hard"
    with pytest.raises(InputError, match="unknown detection mode"):
        gates.check_mode("fuzzy")


def test_occluded_fraction_sums_overlaps_and_caps_at_one():
    # Target 0 at 50 m spans [-0.1, 0.1] rad. Occluders 1 and 2 (20 m) span [-0.14, 0.04] and
    # [-0.04, 0.14]: each covers 0.14 rad = 70 %, summed 140 %, capped at 1. Vehicle 3 (80 m,
    # [-0.5, 0.5]) is farthest: covered by 0 (its whole 0.2 rad) and 1 (0.18 rad).
    r = jnp.array([[50.0], [20.0], [20.0], [80.0]])
    az = jnp.array([[0.0], [-0.05], [0.05], [0.0]])
    half = jnp.array([[0.1], [0.09], [0.09], [0.5]])
    occ = jnp.array([[True], [True], [True], [True]])
    both = np.asarray(occluded_fraction(r, az, half, occ, "hard", 1.0, 0.01))[:, 0]
    assert both[0] == 1.0 and both[1] == 0.0  # 1 and 2 at equal range do not hide each other
    one = np.asarray(occluded_fraction(r, az, half, occ.at[2].set(False), "hard", 1.0, 0.01))
    assert float(one[0, 0]) == pytest.approx(0.7, abs=1e-12)
    assert float(one[3, 0]) == pytest.approx((0.2 + 0.18) / 1.0, abs=1e-12)


def test_detect_batch_passes_mode_and_temperature_through():
    # A car at the camera's resolvability edge at 180 deg (73.335 m): soft p ~ 1/2 moves with the
    # temperature, hard p is 1.
    from diffsense import sensors as sensor

    config = sensor.load_config("camera")
    params = sensor.make_params(config, hfov_deg=180.0)
    one = make_scene([[0.0, config.mount_x_m + 73.335]], [[0.0, 0.0]])
    scenes = jax.tree.map(lambda a: jnp.stack([a, a]), one)
    key = jax.random.key(3, impl="rbg")
    for mode, temperature in (("hard", 1.0), ("soft", 1.0), ("soft", 3.0)):
        batch = sensor.detect_batch(scenes, params, config, key, mode=mode, temperature=temperature)
        single = sensor.p_detect(one, params, config, mode=mode, temperature=temperature)
        np.testing.assert_allclose(np.asarray(batch.p_detect[1]), np.asarray(single), rtol=1e-12)


@pytest.mark.parametrize("name", [
    pytest.param("radar", marks=pytest.mark.xfail(strict=True, reason=(
        "radar_gain_dbi is a strong float64 under x64 (jnp.log10 of a weak scalar is not weak), "
        "so the SNR, the radar's p and noise scales promote a float32 scene to float64"))),
    "camera", "camera hard", "camera paper hard", "camera confidence",
])
def test_float32_scenes_stay_float32(name):
    # Every array the sensor returns has the scene's dtype (no silent float64 promotion), in
    # either mode and profile (the paper profile's hard gates and occlusion order included) and
    # under the confidence law.
    from diffsense import sensors as sensor

    sensor_name, *rest = name.split()
    mode = "hard" if "hard" in rest else "soft"
    config = sensor.load_config(sensor_name, profile="paper" if "paper" in rest else "physical")
    if "confidence" in rest:  # the detector-confidence law (its visible fraction at the edge)
        from diffsense import config as cfg
        from diffsense.sensors._laws import CameraDetection

        config = cfg.replace(config, detection=CameraDetection(law="confidence"))
    scene = make_scene([[0.0, 40.0, 60.0]], [[0.0, 1.0, -3.0]], dtype=np.float32)
    det = jax.jit(sensor.detect, static_argnames=("config", "mode"))(
        scene, config.params, config, jax.random.key(0, impl="rbg"), mode=mode)
    assert {det.p_detect.dtype, det.x_m.dtype, det.y_m.dtype} == {np.dtype(np.float32)}


@pytest.mark.parametrize("turn", [0.2, math.pi - 0.02, -2.5])
def test_occluded_fraction_depends_on_azimuth_differences_only(turn):
    # The scene of the test above (occluder 2 this time) turned by `turn`: the same fractions.
    # Turned by pi - 0.02, occluder 2 lands at -pi + 0.03 and the car it covers at pi - 0.02.
    r = jnp.array([[50.0], [20.0], [20.0], [80.0]])
    az = jnp.array([[0.0], [-0.05], [0.05], [0.0]])
    half = jnp.array([[0.1], [0.09], [0.09], [0.5]])
    occ = jnp.array([[True], [False], [True], [True]])
    base = np.asarray(occluded_fraction(r, az, half, occ, "hard", 1.0, 0.01))
    turned = np.asarray(occluded_fraction(r, geo.wrap_angle(az + turn), half, occ, "hard", 1.0, 0.01))
    np.testing.assert_allclose(turned, base, atol=1e-12)
    np.testing.assert_allclose(base[:, 0], [0.7, 0.0, 0.0, 0.38], atol=1e-12)


def test_a_zero_width_vehicle_is_not_occluded_and_has_a_finite_gradient():
    r = jnp.array([[50.0], [20.0]])
    az = jnp.array([[0.0], [0.0]])
    occ = jnp.array([[True], [True]])

    def frac(h0):
        half = jnp.array([[0.0], [0.1]]).at[0, 0].set(h0)
        return occluded_fraction(r, az, half, occ, "soft", 1.0, 0.01)[0, 0]

    assert float(frac(0.0)) == 0.0
    assert np.isfinite(float(jax.grad(frac)(0.0)))
