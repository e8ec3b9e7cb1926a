"""Sensor physics: radar link budget, camera projection and depth noise, mounting, occlusion, noise."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_sensor_scenes import jit_detect, jit_p_detect, make_scene, traffic_scene

from diffsense import config as cfg
from diffsense import sensors as sensor
from diffsense.scene import CAR, TRUCK, VAN
from diffsense.sensors._geometry import Tracks
from diffsense.sensors._inspect import boresight_report
from diffsense.sensors._radar import _radar_terms

RADAR = sensor.load_config("radar")
jit_terms = jax.jit(lambda tracks, params, config, mode: _radar_terms(tracks, params, config, mode, 1.0),
                    static_argnames=("config", "mode"))
CAMERA = sensor.load_config("camera")
KEY = jax.random.key(7, impl="rbg")  # threefry compiles ~3 s slower on CPU


def snr(range_m, hfov_deg=30.0, config=RADAR, rcs=10.0):
    params = sensor.make_params(config, hfov_deg=hfov_deg)
    return float(sensor.radar_snr_db(jnp.asarray(range_m), rcs, params, config))


def test_snr_falls_12_04_db_per_range_doubling():
    no_air = cfg.replace(RADAR, atmospheric_loss_db_per_km=0.0)
    for r in (10.0, 50.0, 100.0):
        assert snr(r, config=no_air) - snr(2 * r, config=no_air) == pytest.approx(12.0412, abs=1e-4)
        # with the atmosphere: plus the two-way absorption over the extra r metres
        extra = 2 * RADAR.atmospheric_loss_db_per_km * r / 1000
        assert snr(r) - snr(2 * r) == pytest.approx(12.0412 + extra, abs=1e-4)


def test_widening_the_beam_costs_two_way_gain():
    assert snr(80.0, 30.0) - snr(80.0, 60.0) == pytest.approx(6.0206, abs=1e-4)
    assert snr(80.0, 30.0) - snr(80.0, 180.0) == pytest.approx(15.563, abs=1e-3)
    gain = float(sensor.radar_gain_dbi(RADAR.params, RADAR))
    assert gain == pytest.approx(10 * math.log10(0.6 * 4 * math.pi / math.radians(30) ** 2 * 2), abs=1e-9)


def test_link_budget_value_at_100_m():
    # Hand calculation in configs/sensors/radar.toml: 16.78 dB for a car at 100 m, HFOV 30 deg.
    assert snr(100.0) == pytest.approx(16.78, abs=0.01)


def test_bigger_vehicles_reflect_more():
    rcs = sensor.radar_rcs_dbsm(jnp.asarray([CAR, VAN, TRUCK]), RADAR)
    assert float(rcs[0]) == 10.0 and float(rcs[0]) < float(rcs[1]) < float(rcs[2])


def test_narrow_radar_sees_to_max_range_and_wide_radar_shrinks():
    reports = {h: boresight_report(sensor.make_params(RADAR, hfov_deg=h), RADAR, 100.0)
               for h in (30.0, 60.0, 90.0, 180.0)}
    assert 100.0 < reports[30.0]["snr_range_m"] < 140.0
    assert reports[30.0]["effective_range_m"] == 100.0
    ranges = [reports[h]["snr_range_m"] for h in (30.0, 60.0, 90.0, 180.0)]
    assert all(a > b for a, b in zip(ranges, ranges[1:]))
    # each HFOV doubling (-6.02 dB) shrinks the SNR-limited range by 10^(-6.02/40) = 1/sqrt(2)
    assert ranges[1] / ranges[0] == pytest.approx(2 ** -0.5, rel=0.01)
    assert reports[180.0]["effective_range_m"] < 60.0
    assert reports[30.0]["snr_db"] == pytest.approx(snr(100.0))


def test_camera_pixels_per_radian_match_table_ii():
    k = float(sensor.camera_px_per_rad(CAMERA.params))
    assert k == pytest.approx(1280 / math.radians(30))
    assert abs(k - 2400) / 2400 < 0.03


def test_stereo_depth_noise_formula_and_hfov_cost():
    z = jnp.asarray([10.0, 50.0])
    sigma = np.asarray(sensor.camera_depth_sigma_m(z, CAMERA.params, CAMERA))
    k = 1280 / math.radians(30)
    np.testing.assert_allclose(sigma, np.asarray(z) ** 2 * 0.5 / (k * 0.12), rtol=1e-12)
    wide = sensor.make_params(CAMERA, hfov_deg=120.0)
    assert float(sensor.camera_depth_sigma_m(50.0, wide, CAMERA)) == pytest.approx(4 * sigma[1])


def _noise_free_camera():
    return cfg.replace(CAMERA, disparity_error_px=0.0, bearing_error_px=0.0)


def test_measurements_return_to_the_world_with_the_ego_pose():
    # Ego rotated by 30 deg at (5, -2); targets placed in the ego frame, converted to the world.
    yaw = math.radians(30)
    rel = np.array([[0.0, 0.0], [40.0, 3.0], [25.0, -6.0]])
    c, s = math.cos(yaw), math.sin(yaw)
    x = 5.0 + c * rel[:, 0] - s * rel[:, 1]
    y = -2.0 + s * rel[:, 0] + c * rel[:, 1]
    scene = make_scene(x[None], y[None], heading_rad=yaw)
    config = _noise_free_camera()
    params = sensor.make_params(config, hfov_deg=90.0)
    det = jit_detect(scene, params, config, KEY)
    np.testing.assert_allclose(det.x_m, scene.x_m, atol=1e-9)
    np.testing.assert_allclose(det.y_m, scene.y_m, atol=1e-9)
    hard = jit_p_detect(scene, params, config, mode="hard")
    np.testing.assert_array_equal(hard, [[1.0, 1.0, 1.0]])


def test_sensors_are_mounted_ahead_of_the_ego_reference_point():
    # A vehicle 3.5 m ahead of the ego centre is behind the radar (4.2 m) but ahead of the camera (2.5 m).
    scene = make_scene([[0.0, 3.5]], [[0.0, 0.0]], length_m=[4.5, 0.4], width_m=[1.8, 0.4])
    assert float(jit_p_detect(scene, RADAR.params, RADAR, mode="hard")[0, 1]) == 0.0
    assert float(jit_p_detect(scene, CAMERA.params, CAMERA, mode="hard")[0, 1]) == 1.0


def test_fov_edge_follows_hfov():
    az = np.radians([10.0, 20.0, 40.0])
    r = 30.0
    x = 4.2 + r * np.cos(az)
    y = r * np.sin(az)
    scene = make_scene(np.r_[0.0, x][None], np.r_[0.0, y][None])
    hard = lambda h: np.asarray(jit_p_detect(scene, sensor.make_params(RADAR, hfov_deg=h),  # noqa: E731
                                                RADAR, mode="hard"))[0, 1:]
    np.testing.assert_array_equal(hard(30.0), [1, 0, 0])
    np.testing.assert_array_equal(hard(60.0), [1, 1, 0])
    np.testing.assert_array_equal(hard(100.0), [1, 1, 1])


def _occlusion_scene():
    # ego, a truck 20 m ahead in the ego's lane, a car hidden 40 m ahead right behind it,
    # a car 40 m ahead one lane left (clear), and a padding slot.
    return make_scene([[0.0, 20.0, 40.0, 40.0, 0.0]], [[0.0, 0.0, 0.0, 3.7, 0.0]],
                      length_m=[4.5, 12.0, 4.5, 4.5, 4.5], width_m=[1.8, 2.5, 1.8, 1.8, 1.8],
                      kind=[CAR, TRUCK, CAR, CAR, CAR], present=[True, True, True, True, False])


def test_camera_occlusion_hides_and_radar_occlusion_attenuates():
    scene = _occlusion_scene()
    params = sensor.make_params(CAMERA, hfov_deg=60.0)
    cam = np.asarray(jit_p_detect(scene, params, CAMERA, mode="hard"))[0]
    np.testing.assert_array_equal(cam, [1, 1, 0, 1, 0])
    gates = jit_terms(Tracks.of(scene), RADAR.params, RADAR, "hard")[0]
    snr_margin = np.asarray(gates[2][0])[:, 0]  # SNR - threshold per vehicle
    open_snr = snr(40.0 - RADAR.mount_x_m)  # the hidden car's SNR without the truck
    assert snr_margin[2] + RADAR.snr_threshold_db == pytest.approx(open_snr - RADAR.occlusion_loss_db)
    radar = np.asarray(jit_p_detect(scene, RADAR.params, RADAR, mode="hard"))[0]
    np.testing.assert_array_equal(radar, [1, 1, 1, 1, 0])


def test_ego_is_known_and_padding_is_never_detected():
    scene = traffic_scene(num_frames=5)
    for config in (RADAR, CAMERA):
        det = jit_detect(scene, config.params, config, KEY)
        np.testing.assert_array_equal(det.p_detect[:, 0], 1.0)
        np.testing.assert_array_equal(det.x_m[:, 0], scene.x_m[:, 0])
        np.testing.assert_array_equal(det.p_detect[:, -1], 0.0)


def test_common_random_numbers_only_the_scale_depends_on_r():
    scene = traffic_scene(num_frames=5)
    config = cfg.replace(CAMERA, bearing_error_px=0.0)
    errors = []
    for hfov in (30.0, 60.0):
        det = jit_detect(scene, sensor.make_params(config, hfov_deg=hfov), config, KEY)
        sx = scene.x_m[:, :1] + config.mount_x_m
        measured = np.hypot(det.x_m - sx, det.y_m - scene.y_m[:, :1])
        true = np.hypot(scene.x_m - sx, scene.y_m - scene.y_m[:, :1])
        errors.append((measured - true)[:, 1:-1])
    # sigma_Z scales with 1 / k = HFOV / width: doubling the HFOV doubles every error
    np.testing.assert_allclose(errors[1], 2 * errors[0], rtol=1e-9)
    again = jit_detect(scene, config.params, config, KEY)
    first = jit_detect(scene, config.params, config, KEY)
    np.testing.assert_array_equal(again.x_m, first.x_m)
    other = jit_detect(scene, config.params, config, jax.random.key(8, impl="rbg"))
    assert not np.allclose(other.x_m[:, 1:-1], first.x_m[:, 1:-1])


def test_radar_noise_grows_at_low_snr():
    scene = make_scene([[0.0, 20.0, 110.0]], [[0.0, 0.0, 0.0]])
    terms = jit_terms(Tracks.of(scene), RADAR.params, RADAR, "soft")
    range_sigma = np.asarray(terms[3])[:, 0]
    assert range_sigma[1] == pytest.approx(0.4, abs=0.01)  # accuracy floor at high SNR
    assert range_sigma[2] > range_sigma[1]
