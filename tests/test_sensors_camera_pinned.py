"""The camera (`diffsense/sensors/_camera.py`) pinned against hand values where the soft model's
temperature and the confidence law's occlusion term had no independent check.

Expected values are hand calculations from configs/sensors/camera.toml (temperatures 0.5 deg,
1.8 m, 1 px, 0.05 of the width; min width 10 px, min visible 0.6) and the paper's Table II
(1280 px, equidistant lens k = W / HFOV_rad). A car seen straight from behind is 1.8 m wide:
its image is k * 2 atan(0.9 / R) px wide.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from _sensor_temperature import assert_temperature_scales_the_config
from test_sensor_scenes import make_scene

from diffsense import config as cfg
from diffsense import sensors as sensor
from diffsense.sensors._camera import _camera_terms, camera_accuracy_px_per_rad
from diffsense.sensors._geometry import Tracks
from diffsense.sensors._laws import CameraDetection

CAMERA = sensor.load_config("camera")
CONFIDENCE = cfg.replace(CAMERA, detection=CameraDetection(law="confidence"))
MOUNT = CAMERA.mount_x_m  # 2.5 m


def _sigmoid(z):
    return 1.0 / (1.0 + math.exp(-z))


def _terms(config, scene, temperature=1.0, mode="soft"):
    return _camera_terms(Tracks.of(scene), config.params, config, mode, temperature)


def _car(range_m, azimuth_deg=0.0):
    """The ego at the origin and one heading-0 car at (range, azimuth) from the camera."""
    az = math.radians(azimuth_deg)
    return make_scene([[0.0, MOUNT + range_m * math.cos(az)]], [[0.0, range_m * math.sin(az)]])


def _p(scene, hfov, config=CAMERA, temperature=1.0):
    params = sensor.make_params(config, hfov_deg=hfov)
    return float(sensor.camera_p_detect(scene, params, config, temperature=temperature)[0, 1])


# --- the temperature ------------------------------------------------------------------------
# At T = 2 the gates' temperatures are 1 deg, 3.6 m, 2 px and 0.1; a gate whose temperature were
# divided by T instead (0.25 deg, 0.9 m, 0.5 px, 0.025) moves each p below by > 1e-2.
#  (a) HFOV 30 deg, car 100.9 m ahead: range margin -0.9 m; width 2444.62 * 2 atan(0.9 / 100.9)
#      = 43.6 px (margin 33.6 px: gate 1 - 5e-8); FOV margin 15 deg (1 - 3e-7); visible margin 0.4.
#  (b) HFOV 30 deg, car 30 m away at 15.3 deg: FOV margin -0.3 deg; visible margin 0.4; the width
#      (> 100 px) and range (70 m) gates ~1.
#  (c) HFOV 180 deg, car 72 m ahead: k = 1280 / pi = 407.437 px/rad, width
#      407.437 * 2 atan(0.0125) = 10.18534 px (margin 0.18534 px); visible margin 0.4; range
#      margin 28 m (gate 0.99958 at T = 2).
def _width_px(k, r):
    return k * 2 * math.atan(0.9 / r)


CASES_T2 = {
    "range": (_car(100.9), 30.0, lambda t: _sigmoid(-0.9 / (1.8 * t)) * _sigmoid(0.4 / (0.05 * t))),
    "fov": (_car(30.0, 15.3), 30.0, lambda t: _sigmoid(-0.3 / (0.5 * t)) * _sigmoid(0.4 / (0.05 * t))),
    "width": (_car(72.0), 180.0,
              lambda t: (_sigmoid((_width_px(1280 / math.pi, 72.0) - 10.0) / t) * _sigmoid(0.4 / (0.05 * t))
                         * _sigmoid(28.0 / (1.8 * t)))),
}


@pytest.mark.parametrize("case", list(CASES_T2))
def test_soft_p_at_temperature_2_by_hand(case):
    scene, hfov, hand = CASES_T2[case]
    p = _p(scene, hfov, temperature=2.0)
    assert p == pytest.approx(hand(2.0), rel=2e-6)
    assert abs(hand(0.5) - p) > 1e-2  # what the temperature divided by T would give


def test_visible_gate_at_temperature_2_by_hand():
    # A car 50 m ahead at 30 deg: the visible gate sigmoid(0.4 / 0.1) = sigmoid(4) = 0.982014
    # (divided by T: sigmoid(16) = 1 - 1e-7), times the range gate sigmoid(50 / 3.6), the FOV
    # gate sigmoid(15 / 1) and the width gate (2444.62 * 2 atan(0.9 / 50) = 88.0 px: 1 - 1e-17).
    p = _p(_car(50.0), 30.0, temperature=2.0)
    assert p == pytest.approx(_sigmoid(4.0) * _sigmoid(50 / 3.6) * _sigmoid(15.0), rel=1e-9)


def _occluded():
    """Ego; an occluder 38 m ahead of the camera, 1.6 m to the left; a car 40 m ahead: the
    occluder is two near-temperatures nearer and covers part of the car."""
    return make_scene([[0.0, MOUNT + 38.0, MOUNT + 40.0]], [[0.0, 1.6, 0.0]])


@pytest.mark.parametrize("temperature", [2.0, 0.5])
def test_temperature_multiplies_every_soft_temperature_occlusion_included(temperature):
    # gate 3 carries the soft occlusion; it moves by > 0.01 between temperatures 2 and 1/2
    assert_temperature_scales_the_config(_camera_terms, CAMERA, _occluded(), temperature, gate=3, vehicle=2,
                                         least=0.01)


# --- the confidence law: the hidden part removes evidence -----------------------------------
def test_confidence_law_scales_the_mean_by_the_unhidden_fraction():
    # Hard occlusion geometry (exact nearer and overlap): the hidden fraction h of the car 40 m
    # ahead is the margin plus 0.6 taken from 1, h = 0.4 - margin of the threshold law's visible gate.
    # The confidence law's mean is 0.95 * size * (1 - h), size = sigmoid((w - 10) / 2) with w the
    # car's width in px at 30 deg (2444.62 * 2 atan(0.9 / 40) = 110.0 px: size = 1 - 2e-22),
    # and p = Phi((mean - 0.6) / 0.1) times the range term P(40 + N(0, sigma_Z) <= 100) = 1.
    scene = _occluded()
    margin = float(_terms(CAMERA, scene, mode="hard")[0][3][0][2, 0])
    hidden = 0.4 - margin
    assert 0.1 < hidden < 0.5, hidden
    mean = 0.95 * (1.0 - hidden)
    phi = 0.5 * math.erfc(-(mean - 0.6) / 0.1 / math.sqrt(2.0))
    params = sensor.make_params(CONFIDENCE, hfov_deg=30.0)
    p = float(sensor.camera_p_detect(scene, params, CONFIDENCE, mode="hard")[0, 2])
    assert p == pytest.approx(phi, rel=1e-6)


def test_confidence_law_reads_the_cars_width_in_pixels():
    # HFOV 180 deg: k = 1280 / pi = 407.437 px/rad; the car 72 m ahead is k 2 atan(0.9 / 72) =
    # 10.18539 px wide, near the law's 10 px half point: size = sigmoid(0.18539 / 2) = 0.52316,
    # mean = 0.95 size = 0.49700, P(confidence >= 0.6) = Phi((mean - 0.6) / 0.1) = 0.15150. The
    # range term: sigma_Z = 72^2 0.5 / (k 0.12) = 53.014 m, P(72 + N(0, sigma_Z) <= 100) =
    # Phi(28 / 53.014) = 0.70131. (Read as 3 atan(0.9 / 72) wide, p would be 0.700.)
    k = 1280.0 / math.pi
    size = _sigmoid((_width_px(k, 72.0) - 10.0) / 2.0)
    confidence = 0.5 * math.erfc(-(0.95 * size - 0.6) / 0.1 / math.sqrt(2.0))
    sigma_z = math.hypot(72.0**2 * 0.5 / (k * 0.12), 1e-3)
    in_range = 0.5 * math.erfc(-(28.0 / sigma_z) / math.sqrt(2.0))
    assert confidence == pytest.approx(0.15150, abs=1e-5) and in_range == pytest.approx(0.70131, abs=1e-5)
    params = sensor.make_params(CONFIDENCE, hfov_deg=180.0)
    p = float(sensor.camera_p_detect(_car(72.0), params, CONFIDENCE, mode="hard")[0, 1])
    # The scene is float32: its 1e-7 relative rounding of the width moves p by 2e-6 here (steep Phi).
    assert p == pytest.approx(confidence * in_range, rel=1e-5)


@pytest.mark.parametrize("hfov", [30, 30.0])
def test_paper_profile_accuracy_is_the_focal_length_whatever_the_hfovs_type(hfov):
    # An HFOV given as an integer must not make the fixed focal length an integer (2400.5 px/rad).
    paper = cfg.replace(CAMERA, accuracy_follows_hfov=False, focal_length_px=2400.5)
    params = dataclasses.replace(CAMERA.params, hfov_deg=hfov)
    assert float(camera_accuracy_px_per_rad(params, paper)) == 2400.5
