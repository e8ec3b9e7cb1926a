"""The inspection helpers behind `python -m diffsense.sensors inspect` (`_inspect.py`): the probe
scene and the coverage field, against hand values.

The shipped radar: HFOV 30 deg and range 100 m, mounted 4.2 m ahead of the ego's centre, a car
10 dBsm, a truck 20 dBsm. The shipped camera: 1280 px wide, mounted 2.5 m ahead; it resolves a
vehicle at least 10 px wide.
"""

from __future__ import annotations

import math
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.scene import CAR, EGO, TARGET, TRUCK
from diffsense.sensors import Camera, make_params
from diffsense.sensors._inspect import boresight_report, coverage_field, probe_scene
from diffsense.sensors._config import load_config

ROOT = Path(__file__).resolve().parents[1]
RADAR, CAMERA = load_config("radar"), load_config("camera")
# At HFOV 180 deg the lens gives k = 1280 px / pi rad = 407.4 px/rad: a 1.8 m wide car spans the
# 10 px out to 0.9 m / tan(5 px / k) = 73.33 m from the camera.
WIDE_CAMERA = make_params(CAMERA, hfov_deg=180.0)
K_WIDE = 1280.0 / math.pi
RESOLVABLE_M = 0.9 / math.tan(5.0 / K_WIDE)


def test_probe_scene_is_the_ego_at_the_origin_and_one_probe_per_point():
    scene = probe_scene(jnp.asarray([10.0, 20.0, 30.0]), jnp.asarray([1.0, -2.0, 0.0]), kind=TRUCK,
                        length_m=12.0, width_m=2.5)
    np.testing.assert_array_equal(np.asarray(scene.x_m), [[0, 10], [0, 20], [0, 30]])
    np.testing.assert_array_equal(np.asarray(scene.y_m), [[0, 1], [0, -2], [0, 0]])
    np.testing.assert_array_equal(np.asarray(scene.role), [EGO, TARGET])
    np.testing.assert_array_equal(np.asarray(scene.kind), [CAR, TRUCK])
    np.testing.assert_array_equal(np.asarray(scene.length_m), [4.5, 12.0])
    np.testing.assert_array_equal(np.asarray(scene.width_m), [1.8, 2.5])


def test_radar_coverage_field_by_hand():
    config = load_config("radar")
    x = np.array([20.0, 60.0, 150.0])
    y = np.array([0.0, 40.0])
    field = coverage_field(config.params, config, x, y, mode="hard")
    # row y = 0: 15.8 and 55.8 m straight ahead are seen, 145.8 m is past the 100 m range;
    # row y = 40: 68 and 36 deg off the axis, outside the +-15 deg field of view
    np.testing.assert_array_equal(field, [[1.0, 1.0, 0.0], [0.0, 0.0, 0.0]])


def test_probe_scene_is_a_whole_scene_on_a_straight_road_along_x():
    x, y = jnp.asarray([10.0, 20.0], jnp.float32), jnp.asarray([1.0, -2.0], jnp.float32)
    scene = probe_scene(x, y, length_m=4.5, width_m=1.8)
    np.testing.assert_array_equal(np.asarray(scene.s_m), np.asarray(scene.x_m))  # arc length = x
    np.testing.assert_array_equal(np.asarray(scene.d_m), np.asarray(scene.y_m))  # offset = y
    for still in (scene.heading_rad, scene.road_angle_rad, scene.speed_mps, scene.lane):
        np.testing.assert_array_equal(np.asarray(still), np.zeros((2, 2)))
    for field in (scene.s_m, scene.d_m, scene.heading_rad, scene.road_angle_rad, scene.speed_mps,
                  scene.length_m, scene.width_m):
        assert field.dtype == jnp.float32  # the grid's float type throughout
    assert scene.lane.dtype == scene.kind.dtype == scene.role.dtype == jnp.int32
    assert scene.present.dtype == jnp.bool_ and bool(scene.present.all())


def test_the_coverage_field_resolves_the_car_to_its_hand_range():
    x = CAMERA.mount_x_m + np.array([RESOLVABLE_M - 1.0, RESOLVABLE_M + 1.0])
    np.testing.assert_array_equal(coverage_field(WIDE_CAMERA, CAMERA, x, np.zeros(1), mode="hard"), [[1.0, 0.0]])
    # 2.8 m wide: 2.8 / 1.8 times as far, so both are resolved.
    wide = coverage_field(WIDE_CAMERA, CAMERA, x, np.zeros(1), mode="hard", width_m=2.8)
    np.testing.assert_array_equal(wide, [[1.0, 1.0]])
    # An integer grid is the same grid (67.5 and 77.5 m from the camera), not an integer car.
    whole = coverage_field(WIDE_CAMERA, CAMERA, np.array([70, 80]), np.array([0]), mode="hard")
    np.testing.assert_array_equal(whole, [[1.0, 0.0]])
    # Soft by default: just inside the range, seen with a probability below 1.
    soft = coverage_field(WIDE_CAMERA, CAMERA, x, np.zeros(1))
    np.testing.assert_array_equal(soft, coverage_field(WIDE_CAMERA, CAMERA, x, np.zeros(1), mode="soft"))
    assert 0.5 < soft[0, 0] < 1.0 and 0.0 < soft[0, 1] < 0.5


def test_a_truck_is_seen_past_the_cars_snr_range():
    # 10 dB more RCS: the R^4 law gives 10^(10/40) = 1.78 times the car's SNR-limited range (the
    # atmosphere's small loss takes a little off).
    wide = make_params(RADAR, hfov_deg=120.0)
    car, truck = boresight_report(wide, RADAR, 80.0), boresight_report(wide, RADAR, 80.0, kind=TRUCK)
    assert truck["snr_range_m"] == pytest.approx(10 ** 0.25 * car["snr_range_m"], rel=0.01)
    assert car["snr_range_m"] < 80.0 < truck["effective_range_m"] == 100.0
    assert (car["p_detect_hard"], truck["p_detect_hard"]) == (0.0, 1.0)
    x = np.array([RADAR.mount_x_m + 80.0])
    assert coverage_field(wide, RADAR, x, np.zeros(1), mode="hard", kind=TRUCK)[0, 0] == 1.0
    assert coverage_field(wide, RADAR, x, np.zeros(1), mode="hard")[0, 0] == 0.0


def test_boresight_reports_name_their_numbers():
    radar = boresight_report(RADAR.params, RADAR, 50.0)
    assert (radar["hfov_deg"], radar["at_range_m"], radar["snr_threshold_db"]) == (30.0, 50.0, 13.2)
    camera = boresight_report(WIDE_CAMERA, CAMERA, 50.0)
    assert (camera["hfov_deg"], camera["at_range_m"]) == (180.0, 50.0)
    assert camera["px_per_rad"] == pytest.approx(K_WIDE, rel=1e-12)
    assert camera["width_px_at_range"] == pytest.approx(2.0 * math.atan(0.9 / 50.0) * K_WIDE, rel=1e-12)
    assert camera["resolvable_range_m"] == pytest.approx(RESOLVABLE_M, rel=1e-12)
    assert camera["effective_range_m"] == pytest.approx(RESOLVABLE_M, rel=1e-12)  # below the 100 m range


def test_the_default_probe_is_the_4_5_m_car_also_where_its_length_counts():
    # Under the confidence law the camera sees the share of the footprint's extent across the line
    # of sight, |L sin(rel)| + |W cos(rel)|, inside its field: 14.4 deg off the axis, next to the
    # 15-deg edge, a longer car pokes further out and is seen less.
    camera = Camera.from_toml(ROOT / "configs" / "sensors" / "laws" / "camera_confidence.toml").config
    x, y = np.array([53.0]), np.array([-13.0])
    default = coverage_field(camera.params, camera, x, y)
    np.testing.assert_array_equal(default, coverage_field(camera.params, camera, x, y, length_m=4.5, width_m=1.8))
    assert coverage_field(camera.params, camera, x, y, length_m=5.5)[0, 0] < default[0, 0] - 0.01
