"""What a sensor setting means in numbers (`boresight_report`, `coverage_field`, behind
`python -m diffsense.sensors inspect`), against hand values: the shipped radar (HFOV 30 deg,
range 100 m, 4.2 m ahead, a car 10 dBsm, a truck 20 dBsm) and camera (1280 px, 2.5 m ahead,
a vehicle resolved while at least 10 px wide), and the paper profile's."""

from __future__ import annotations

import math
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest
from _laws import threshold_config

from diffsense.scene import CAR, EGO, TARGET, TRUCK
from diffsense.sensors import (
    Camera,
    boresight_report,
    coverage_field,
    load_config,
    make_params,
    probe_scene,
)

ROOT = Path(__file__).resolve().parents[1]
RADAR, CAMERA = threshold_config("radar"), threshold_config("camera")
# At HFOV 180 deg the lens gives k = 1280 px / pi rad = 407.4 px/rad: a 1.8 m wide car spans the
# 10 px out to 0.9 m / tan(5 px / k) = 73.33 m from the camera.
WIDE_CAMERA = make_params(CAMERA, hfov_deg=180.0)
K_WIDE = 1280.0 / math.pi
RESOLVABLE_M = 0.9 / math.tan(5.0 / K_WIDE)


def test_the_probe_scene_is_the_ego_at_the_origin_and_one_probe_per_point_on_a_straight_road():
    scene = probe_scene(jnp.asarray([10.0, 20.0], jnp.float32), jnp.asarray([1.0, -2.0], jnp.float32), kind=TRUCK,
                        length_m=12.0, width_m=2.5)
    for xy in (scene.x_m, scene.s_m):  # arc length = x, offset = y
        np.testing.assert_array_equal(np.asarray(xy), [[0, 10], [0, 20]])
    for yd in (scene.y_m, scene.d_m):
        np.testing.assert_array_equal(np.asarray(yd), [[0, 1], [0, -2]])
    for still in (scene.heading_rad, scene.road_angle_rad, scene.speed_mps, scene.lane):
        np.testing.assert_array_equal(np.asarray(still), np.zeros((2, 2)))
    assert (scene.role.tolist(), scene.kind.tolist()) == ([EGO, TARGET], [CAR, TRUCK])
    np.testing.assert_array_equal(np.asarray(scene.length_m), np.float32([4.5, 12.0]))
    np.testing.assert_array_equal(np.asarray(scene.width_m), np.float32([1.8, 2.5]))
    assert {a.dtype for a in (scene.s_m, scene.d_m, scene.heading_rad, scene.road_angle_rad, scene.speed_mps,
                              scene.length_m, scene.width_m)} == {np.dtype(np.float32)}  # the grid's float type
    assert scene.lane.dtype == scene.kind.dtype == scene.role.dtype == jnp.int32
    assert scene.present.dtype == jnp.bool_ and bool(scene.present.all())


def test_the_radar_coverage_field_by_hand():
    # row y = 0: 15.8 and 55.8 m straight ahead are seen, 145.8 m is past the 100 m range;
    # row y = 40: 68 and 36 deg off the axis, outside the +-15 deg field of view
    field = coverage_field(RADAR.params, RADAR, np.array([20.0, 60.0, 150.0]), np.array([0.0, 40.0]), mode="hard")
    np.testing.assert_array_equal(field, [[1.0, 1.0, 0.0], [0.0, 0.0, 0.0]])


def test_the_coverage_field_resolves_the_car_to_its_hand_range():
    x = CAMERA.mount_x_m + np.array([RESOLVABLE_M - 1.0, RESOLVABLE_M + 1.0])
    np.testing.assert_array_equal(coverage_field(WIDE_CAMERA, CAMERA, x, np.zeros(1), mode="hard"), [[1.0, 0.0]])
    # 2.8 m wide: 2.8 / 1.8 times as far, so both are resolved.
    np.testing.assert_array_equal(coverage_field(WIDE_CAMERA, CAMERA, x, np.zeros(1), mode="hard", width_m=2.8),
                                  [[1.0, 1.0]])
    # An integer grid is the same grid (67.5 and 77.5 m from the camera), not an integer car.
    whole = coverage_field(WIDE_CAMERA, CAMERA, np.array([70, 80]), np.array([0]), mode="hard")
    np.testing.assert_array_equal(whole, [[1.0, 0.0]])
    # Soft by default: just inside the range, seen with a probability below 1.
    soft = coverage_field(WIDE_CAMERA, CAMERA, x, np.zeros(1))
    np.testing.assert_array_equal(soft, coverage_field(WIDE_CAMERA, CAMERA, x, np.zeros(1), mode="soft"))
    assert 0.5 < soft[0, 0] < 1.0 and 0.0 < soft[0, 1] < 0.5


def test_the_default_probe_is_the_4_5_m_car_also_where_its_length_counts():
    # Under the confidence law the camera sees the share of the footprint's extent across the line
    # of sight, |L sin(rel)| + |W cos(rel)|, inside its field: 14.4 deg off the axis, next to the
    # 15 deg edge, a longer car pokes further out and is seen less.
    camera = Camera.from_toml(ROOT / "configs" / "sensors" / "laws" / "camera_confidence.toml").config
    x, y = np.array([53.0]), np.array([-13.0])
    default = coverage_field(camera.params, camera, x, y)
    np.testing.assert_array_equal(default, coverage_field(camera.params, camera, x, y, length_m=4.5, width_m=1.8))
    assert coverage_field(camera.params, camera, x, y, length_m=5.5)[0, 0] < default[0, 0] - 0.01


def test_a_narrow_radar_sees_to_its_range_and_a_wider_one_less_far():
    reports = {h: boresight_report(make_params(RADAR, hfov_deg=h), RADAR, 100.0) for h in (30.0, 60.0, 90.0, 180.0)}
    ranges = [reports[h]["snr_range_m"] for h in (30.0, 60.0, 90.0, 180.0)]
    assert 100.0 < ranges[0] < 140.0 and reports[30.0]["effective_range_m"] == 100.0
    assert all(a > b for a, b in zip(ranges, ranges[1:]))
    # each HFOV doubling (-6.02 dB) shrinks the SNR-limited range by 10^(-6.02/40) = 1/sqrt(2)
    assert ranges[1] / ranges[0] == pytest.approx(2 ** -0.5, rel=0.01)
    assert reports[180.0]["effective_range_m"] < 60.0
    # Six times the beam costs 20 log10(6) = 15.56 dB and a factor 6^(-1/2) of the range: 122.7 -> 50.1 m.
    assert reports[30.0]["snr_db"] - reports[180.0]["snr_db"] == pytest.approx(20 * math.log10(6.0), abs=0.02)
    assert 49.0 < reports[180.0]["effective_range_m"] < 51.0
    assert reports[30.0]["snr_db"] == pytest.approx(16.778781, abs=1e-5)  # the hand budget at 100 m


def test_a_truck_is_seen_past_the_cars_snr_range():
    # 10 dB more RCS: 10^(10/40) = 1.78 times the car's SNR-limited range (less the atmosphere's share).
    wide = make_params(RADAR, hfov_deg=120.0)
    car, truck = boresight_report(wide, RADAR, 80.0), boresight_report(wide, RADAR, 80.0, kind=TRUCK)
    assert truck["snr_range_m"] == pytest.approx(10 ** 0.25 * car["snr_range_m"], rel=0.01)
    assert car["snr_range_m"] < 80.0 < truck["effective_range_m"] == 100.0
    assert (car["p_detect_hard"], truck["p_detect_hard"]) == (0.0, 1.0)
    x = np.array([RADAR.mount_x_m + 80.0])
    assert coverage_field(wide, RADAR, x, np.zeros(1), mode="hard", kind=TRUCK)[0, 0] == 1.0
    assert coverage_field(wide, RADAR, x, np.zeros(1), mode="hard")[0, 0] == 0.0


def test_the_reports_name_their_numbers():
    radar = boresight_report(RADAR.params, RADAR, 99.0)
    assert (radar["hfov_deg"], radar["at_range_m"], radar["snr_threshold_db"]) == (30.0, 99.0, 13.2)
    camera = boresight_report(WIDE_CAMERA, CAMERA, 50.0)
    assert (camera["hfov_deg"], camera["at_range_m"]) == (180.0, 50.0)
    assert camera["px_per_rad"] == pytest.approx(K_WIDE, rel=1e-12)
    assert camera["width_px_at_range"] == pytest.approx(2.0 * math.atan(0.9 / 50.0) * K_WIDE, rel=1e-12)
    assert camera["resolvable_range_m"] == pytest.approx(RESOLVABLE_M, rel=1e-12)
    assert camera["effective_range_m"] == pytest.approx(RESOLVABLE_M, rel=1e-12)  # below the 100 m range
    # At 30 deg (k = 2444.6 px/rad) a car is 10 px wide out to 440.03 m (1.8 k / 10 to 1.4e-6).
    narrow = boresight_report(CAMERA.params, CAMERA, 50.0)
    k = 1280.0 / math.radians(30.0)
    assert narrow["resolvable_range_m"] == pytest.approx(1.8 * k / 10.0, rel=1e-5)
    assert narrow["resolvable_range_m"] == pytest.approx(440.03, abs=0.01)
    at_limit = boresight_report(CAMERA.params, CAMERA, narrow["resolvable_range_m"])
    assert at_limit["width_px_at_range"] == pytest.approx(10.0, rel=1e-12)


@pytest.mark.parametrize("hfov", [30.0, 180.0])
def test_the_paper_radar_sees_100_m_at_every_hfov_and_the_paper_camera_has_table_iis_accuracy(hfov):
    paper = load_config("radar", profile="paper")
    report = boresight_report(make_params(paper, hfov_deg=hfov), paper, 99.0)
    assert report["effective_range_m"] == pytest.approx(100.0) and report["p_detect_hard"] == 1.0
    beam_sr = math.radians(30.0) * math.radians(15.0)  # the 30 x 15 deg beam's gain
    assert report["gain_dbi"] == pytest.approx(10 * math.log10(0.6 * 4 * math.pi / beam_sr), abs=1e-9)
    paper = load_config("camera", profile="paper")
    report = boresight_report(make_params(paper, hfov_deg=hfov), paper, 80.0)
    # sigma_Z = Z^2 * 0.5 px / (2400 px * 0.12 m) at Z = 80 m: 11.11 m, whatever the HFOV
    assert report["depth_sigma_m"] == pytest.approx(80.0**2 * 0.5 / (2400 * 0.12), rel=1e-6)
    assert report["effective_range_m"] == pytest.approx(100.0)
    wide = boresight_report(make_params(CAMERA, hfov_deg=180.0), CAMERA, 80.0)  # the physical lens's k
    assert wide["depth_sigma_m"] == pytest.approx(80.0**2 * 0.5 / (K_WIDE * 0.12), rel=1e-6)
