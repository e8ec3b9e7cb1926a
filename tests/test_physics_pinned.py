"""The sensors' physical numbers pinned against independent values.

Each expected number is a hand calculation written out in the comments (from the constants of
configs/sensors/*.toml and the paper's Tables I and II), or a numpy recomputation written
differently from the model (linear-power radar equation instead of decibels; angular intervals
from the footprint's corners instead of |L sin| + |W cos|; sample statistics of the noisy
measurements instead of the noise scales). tests/test_sensor_physics.py holds the structural
checks (ratios, mounting, FOV edges); these pin the absolute values a one-line slip would move.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import brentq
from test_sensor_scenes import jit_detect, jit_p_detect, make_scene

from diffsense import sensors as sensor
from diffsense.sensors._camera import _camera_terms
from diffsense.sensors._geometry import Tracks
from diffsense.sensors._radar import _radar_terms

RADAR = sensor.load_config("radar")
CAMERA = sensor.load_config("camera")
KEY = jax.random.key(11, impl="rbg")
jit_radar_terms = jax.jit(lambda tracks, params, config: _radar_terms(tracks, params, config, "soft", 1.0),
                          static_argnums=2)
# (margin [V, T], tau) per gate, hard mode
jit_gates = jax.jit(lambda terms, tracks, params, config: terms(tracks, params, config, "hard", 1.0)[0],
                    static_argnums=(0, 3))


def _ahead(config, ranges_m):
    """One frame per range: the ego and one car straight ahead of the sensor at that range."""
    x = np.stack([np.zeros(len(ranges_m)), config.mount_x_m + np.asarray(ranges_m)], axis=1)
    return make_scene(x, np.zeros_like(x))


# --- camera resolvability -------------------------------------------------------------------
# A car seen from behind is 1.8 m wide; its image is k * 2 atan(0.9 / R) px with k = W / HFOV_rad
# (equidistant lens) and must be at least min_width_px = 10 px: R_max = 0.9 / tan(5 / k).
#   30 deg, 1280 px: k = 1280 / 0.523599 = 2444.62 px/rad, R_max = 0.9 / tan(0.0020453) = 440.03 m
#  120 deg, 1280 px: k =  611.15, R_max = 110.005 m;   180 deg, 1280 px: k = 407.44, 73.335 m
#  120 deg, 3840 px: k = 1833.46, R_max = 330.02 m;    180 deg, 3840 px: k = 1222.31, 220.015 m
# (small angles: R_max ~ 1.8 m * k / 10 px = 0.18 k m, within 0.01 % of these).
@pytest.mark.parametrize("hfov, width, r_max", [
    (30.0, 1280.0, 440.03), (120.0, 1280.0, 110.005), (180.0, 1280.0, 73.335),
    (120.0, 3840.0, 330.02), (180.0, 3840.0, 220.015),
])
def test_camera_resolvability_range(hfov, width, r_max):
    params = sensor.make_params(CAMERA, hfov_deg=hfov, width_px=width, range_m=1000.0)
    scene = _ahead(CAMERA, r_max * np.array([0.99, 0.998, 1.002, 1.01]))
    hard = np.asarray(jit_p_detect(scene, params, CAMERA, mode="hard"))[:, 1]
    np.testing.assert_array_equal(hard, [1, 1, 0, 0])
    # Soft, exactly at R_max: the width gate is sigmoid(0) = 1/2, the visible-fraction gate
    # sigmoid((1 - 0.6) / 0.05) = sigmoid(8) = 0.999665, the FOV and range gates ~1.
    soft = float(jit_p_detect(_ahead(CAMERA, [r_max]), params, CAMERA)[0, 1])
    assert soft == pytest.approx(0.5 * 0.999665, abs=2e-4)


def test_camera_default_range_limits_at_120_and_resolution_at_180_deg():
    # Default range 100 m: at 120 deg the car resolves out to 110 m, so the range gate decides
    # (farthest car 100 m); at 180 deg resolvability decides (73.3 m).
    scene = _ahead(CAMERA, [54.0, 56.0, 73.0, 74.0, 99.5, 100.5])
    det = {h: np.asarray(jit_p_detect(scene, sensor.make_params(CAMERA, hfov_deg=h), CAMERA,
                                      mode="hard"))[:, 1] for h in (120.0, 180.0)}
    np.testing.assert_array_equal(det[120.0], [1, 1, 1, 1, 1, 0])
    np.testing.assert_array_equal(det[180.0], [1, 1, 1, 0, 0, 0])


def test_stereo_depth_sigma_by_hand():
    # sigma_Z = Z^2 * 0.5 px / (k * 0.12 m): at 30 deg, 1280 px (k = 2444.62 px/rad),
    # Z = 50 m: 2500 * 0.5 / 293.354 = 4.26106 m; at 120 deg k is 4x smaller: 17.0442 m.
    z = jnp.asarray(50.0)
    assert float(sensor.camera_depth_sigma_m(z, CAMERA.params, CAMERA)) == pytest.approx(4.26106, rel=1e-5)
    wide = sensor.make_params(CAMERA, hfov_deg=120.0)
    assert float(sensor.camera_depth_sigma_m(z, wide, CAMERA)) == pytest.approx(17.0442, rel=1e-5)
    assert float(sensor.camera_px_per_rad(wide)) == pytest.approx(611.155, rel=1e-5)


# --- partial occlusion ----------------------------------------------------------------------
def _interval(sensor_x, x, y, length=4.5, width=1.8):
    """Angular interval (lo, hi) [rad] of a heading-0 car centred at (x, y), seen from
    (sensor_x, 0): its footprint's corners projected across the line of sight, at the centre's
    range (the model's definition, computed from the corners)."""
    dx, dy = x - sensor_x, y
    bearing, r = math.atan2(dy, dx), math.hypot(dx, dy)
    across = np.array([-math.sin(bearing), math.cos(bearing)])
    corners = np.array([[sx * length / 2, sy * width / 2] for sx in (-1, 1) for sy in (-1, 1)])
    proj = corners @ across
    half = math.atan(0.5 * (proj.max() - proj.min()) / r)
    return bearing - half, bearing + half


def _covered(sensor_x, target, occluder):
    lo_t, hi_t = _interval(sensor_x, *target)
    lo_o, hi_o = _interval(sensor_x, *occluder)
    return max(0.0, min(hi_t, hi_o) - max(lo_t, lo_o)) / (hi_t - lo_t)


COVERED = (0.29, 0.39, 0.41, 0.59)  # visible 71 %, 61 % (detected), 59 %, 41 % (not)


def _occlusion_scene(sensor_x):
    """Frame i: a car 40 m ahead of the sensor, and an occluder 20 m ahead shifted sideways so
    that it covers COVERED[i] of the car's angular interval (solved with the reference above)."""
    target = (sensor_x + 40.0, 0.0)
    ys = [brentq(lambda y: _covered(sensor_x, target, (sensor_x + 20.0, y)) - f, 0.0, 3.0, xtol=1e-12)
          for f in COVERED]
    x = np.array([[0.0, sensor_x + 20.0, target[0]]] * len(ys))
    y = np.array([[0.0, yo, 0.0] for yo in ys])
    return make_scene(x, y)


def test_camera_partial_occlusion_around_the_0_6_threshold():
    scene = _occlusion_scene(CAMERA.mount_x_m)
    params = sensor.make_params(CAMERA, hfov_deg=60.0)
    margin = np.asarray(jit_gates(_camera_terms, Tracks.of(scene), params, CAMERA)[3][0])[2]
    np.testing.assert_allclose(margin, 1.0 - np.array(COVERED) - 0.6, atol=1e-6)
    hard = np.asarray(jit_p_detect(scene, params, CAMERA, mode="hard"))
    np.testing.assert_array_equal(hard[:, 2], [1, 1, 0, 0])
    np.testing.assert_array_equal(hard[:, 1], 1)  # the occluder itself is in clear view
    # Soft: p falls as the cover grows; with the other gates ~1 it is the visible-fraction gate
    # sigmoid((0.4 - covered) / 0.05) = sigmoid(2.2, 0.2, -0.2, -3.8) = 0.900, 0.550, 0.450, 0.022
    # (the soft overlap ramp moves the covered fraction by < 0.003: p by < 0.01).
    soft = np.asarray(jit_p_detect(scene, params, CAMERA))[:, 2]
    assert np.all(np.diff(soft) < 0), soft
    np.testing.assert_allclose(soft, [0.900, 0.550, 0.450, 0.022], atol=0.01)


def test_radar_partial_occlusion_costs_15_db_per_covered_fraction():
    # Same geometry seen from the radar's mount: SNR - threshold = SNR(40 m) - 15 dB * covered
    # - 13.2 dB, with SNR(40 m) = 96.8588 - 40 log10(40) - 0.8 * 0.04 = 32.7447 dB (below).
    scene = _occlusion_scene(RADAR.mount_x_m)
    margin = np.asarray(jit_gates(_radar_terms, Tracks.of(scene), RADAR.params, RADAR)[2][0])[2]
    np.testing.assert_allclose(margin, 32.7447 - 15.0 * np.array(COVERED) - 13.2, atol=1e-3)


# --- radar link budget ------------------------------------------------------------------------
# dB budget at HFOV 30 deg, VFOV 15 deg, car (10 dBsm), boresight:
#   Pt 14 + 2 G 34.8079 (G = 10 log10(0.6 * 4 pi / (0.523599 * 0.261799)) = 17.4039 dBi)
#   + 20 log10(3.8934 mm) -48.1934 + 10 - 30 log10(4 pi) 32.9763
#   - noise floor (-174 + 10 log10(25e3) 43.9794 + NF 4.8 = -125.2206 dBm) - loss 6
#   = 96.858781 dB - 40 log10(R) - 2 * 0.4 dB/km * R
# (the far-field equation is clamped at R = 1 mm: 96.858781 + 120 = 216.858780 dB below it).
@pytest.mark.parametrize("range_m, snr_db", [(20.0, 44.801581), (50.0, 28.859981),
                                             (100.0, 16.778781), (200.0, 4.657581),
                                             (0.5, 108.899581), (0.0, 216.858780)])
def test_radar_snr_against_a_hand_link_budget(range_m, snr_db):
    got = float(sensor.radar_snr_db(jnp.asarray(range_m), 10.0, RADAR.params, RADAR))
    assert got == pytest.approx(snr_db, abs=2e-6)
    if range_m < 1.0:
        return
    # The radar equation in linear power with the physical kT0 (1.380649e-23 J/K * 290 K =
    # -173.975 dBm/Hz, which the model rounds to -174): 0.025 dB lower.
    lam, gain = 299792458.0 / 77e9, 0.6 * 4 * math.pi / (math.radians(30) * math.radians(15))
    received_w = 10 ** (14 / 10) * 1e-3 * gain**2 * lam**2 * 10.0 / ((4 * math.pi) ** 3 * range_m**4)
    noise_w = 1.380649e-23 * 290.0 * 25e3 * 10 ** (4.8 / 10)
    losses = 10 ** ((6.0 + 0.8 * range_m / 1000) / 10)
    assert got - 10 * math.log10(received_w / noise_w / losses) == pytest.approx(0.0248, abs=1e-3)


# --- measurement noise: sample statistics over many draws ----------------------------------
DRAWS = 4000  # frames of one static geometry: one (range, azimuth) draw pair each


def _errors(config, params, range_m):
    """Range error [m] and azimuth error [rad] of DRAWS measurements of a car straight ahead."""
    det = jit_detect(_ahead(config, np.full(DRAWS, range_m)), params, config, KEY)
    dx = np.asarray(det.x_m)[:, 1] - config.mount_x_m
    dy = np.asarray(det.y_m)[:, 1]
    return np.hypot(dx, dy) - range_m, np.arctan2(dy, dx)


def _assert_gaussian(errors, sigma):
    # Mean within 3 standard errors of 0, std within 3 standard errors (sigma / sqrt(2 (n - 1)))
    # of sigma.
    n = errors.size
    assert abs(errors.mean()) <= 3 * sigma / math.sqrt(n)
    assert abs(errors.std(ddof=1) - sigma) <= 3 * sigma / math.sqrt(2 * (n - 1))


# Radar noise: sqrt(accuracy^2 + (resolution * 10^(-SNR/20) / sqrt 2)^2) (Table I: accuracy
# 0.4 m / 0.1 deg, resolution 1.8 m / 1.6 deg), SNR from the budget above:
#   20 m, SNR 44.80 dB: thermal factor 10^(-2.240) / sqrt 2 = 0.004077 -> 0.400067 m, 0.100212 deg
#  200 m, SNR 4.658 dB: thermal factor 10^(-0.2329) / sqrt 2 = 0.41352 -> 0.845172 m, 0.669311 deg
# Camera (30 deg, 1280 px, k = 2444.62 px/rad) at 30 m: depth 900 * 0.5 / (k * 0.12) = 1.533981 m,
# bearing 0.5 px / k = 2.04531e-4 rad; at 120 deg both are 4x larger.
@pytest.mark.parametrize("name, hfov, range_m, sigma_r, sigma_az_deg", [
    ("radar", 30.0, 20.0, 0.400067, 0.100212),
    ("radar", 30.0, 200.0, 0.845172, 0.669311),
    ("camera", 30.0, 30.0, 1.533981, math.degrees(2.04531e-4)),
    ("camera", 120.0, 30.0, 4 * 1.533981, math.degrees(4 * 2.04531e-4)),
])
def test_measurement_noise_scales_and_independence(name, hfov, range_m, sigma_r, sigma_az_deg):
    config = RADAR if name == "radar" else CAMERA
    params = sensor.make_params(config, hfov_deg=hfov)
    range_err, az_err = _errors(config, params, range_m)
    _assert_gaussian(range_err, sigma_r)
    # the measured bearing is turned by 2 atan(e / 2) = e (1 - e^2 / 12): < 4e-5 relative here
    _assert_gaussian(az_err, math.radians(sigma_az_deg))
    # range and azimuth come from independent draws: correlation within 3 / sqrt(n) of 0
    assert abs(np.corrcoef(range_err, az_err)[0, 1]) <= 3 / math.sqrt(DRAWS)


@pytest.mark.parametrize("range_m, sigma_r, sigma_az_deg", [(20.0, 0.400067, 0.100212),
                                                           (200.0, 0.845172, 0.669311)])
def test_radar_noise_scales_exactly(range_m, sigma_r, sigma_az_deg):
    # The scales behind the draws above, to 1e-5 (same hand numbers).
    terms = jit_radar_terms(Tracks.of(_ahead(RADAR, [range_m])), RADAR.params, RADAR)
    assert float(terms[3][1, 0]) == pytest.approx(sigma_r, rel=1e-5)
    assert float(terms[4][1, 0]) == pytest.approx(math.radians(sigma_az_deg), rel=1e-5)


def test_noise_draws_are_standard_normal_and_independent():
    draws = np.asarray(sensor.measurement_noise(KEY, _ahead(RADAR, np.full(DRAWS, 50.0))))
    assert draws.shape == (2, DRAWS, 2)
    for d in draws[..., 1]:
        _assert_gaussian(d, 1.0)
    assert abs(np.corrcoef(draws[0, :, 1], draws[1, :, 1])[0, 1]) <= 3 / math.sqrt(DRAWS)


def test_camera_fov_edge_is_half_the_hfov():
    # Cars 30 m from the camera at azimuth 29 / 31 deg (HFOV 60) and 59 / 61 deg (HFOV 120).
    az = np.radians([29.0, 31.0, 59.0, 61.0])
    x = np.stack([np.zeros(4), CAMERA.mount_x_m + 30.0 * np.cos(az)], axis=1)
    y = np.stack([np.zeros(4), 30.0 * np.sin(az)], axis=1)
    scene = make_scene(x, y)
    seen = {h: np.asarray(jit_p_detect(scene, sensor.make_params(CAMERA, hfov_deg=h), CAMERA,
                                       mode="hard"))[:, 1] for h in (60.0, 120.0)}
    np.testing.assert_array_equal(seen[60.0], [1, 0, 0, 0])
    np.testing.assert_array_equal(seen[120.0], [1, 1, 1, 0])


@pytest.mark.parametrize("name", ["radar", "camera"])
def test_sensor_functions_default_to_soft_at_the_documented_temperature(name):
    # A car at the camera's resolvability edge at 180 deg / the radar's 100 m range edge at 30 deg
    # (soft p ~ 1/2 in both).
    config = RADAR if name == "radar" else CAMERA
    params = sensor.make_params(config, hfov_deg=180.0 if name == "camera" else 30.0)
    scene = _ahead(config, [73.335 if name == "camera" else 100.0])
    p_fn = sensor.camera_p_detect if name == "camera" else sensor.radar_p_detect
    det_fn = sensor.camera_detect if name == "camera" else sensor.radar_detect
    explicit = float(p_fn(scene, params, config, mode="soft", temperature=1.0)[0, 1])
    assert 0.2 < explicit < 0.8
    assert float(p_fn(scene, params, config)[0, 1]) == explicit
    assert float(det_fn(scene, params, config, KEY).p_detect[0, 1]) == explicit
    assert float(sensor.p_detect(scene, params, config)[0, 1]) == explicit
    assert float(sensor.detect(scene, params, config, KEY).p_detect[0, 1]) == explicit
