"""The stereo camera against hand values: the f-theta lens (k = width_px / HFOV_rad), the
resolvability of a 1.8 m wide car (k * 2 atan(0.9 / R) >= 10 px), the stereo depth noise
sigma_Z = Z^2 0.5 px / (k 0.12 m), partial occlusion against the 0.6 visible fraction, the soft
gates' temperatures (0.5 deg, 1.8 m, 1 px, 0.05) and the confidence law.
`_camera_terms` (its gates and noise scales) is the physics under test here.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _laws import threshold_config
from _sensor_scenes import (
    COVERED,
    ahead,
    assert_temperature_scales_the_config,
    jit_p_detect,
    make_scene,
    occlusion_scene,
    phi,
    sigmoid,
)

from diffsense import config as cfg
from diffsense import sensors
from diffsense.scene import CAR, TRUCK
from diffsense.sensors._camera import _camera_terms
from diffsense.sensors._geometry import Tracks

CAMERA = threshold_config("camera")  # the gates this file tests
CONFIDENCE = cfg.replace(CAMERA, detection=sensors.CameraDetection(law="confidence"))
hard_gates = jax.jit(lambda scene, params, config: _camera_terms(Tracks.of(scene), params, config, "hard", 1.0)[0],
                     static_argnums=2)


def width_px(k, r):
    return k * 2 * math.atan(0.9 / r)


def p(scene, hfov, config=CAMERA, temperature=1.0, vehicle=1, **kw):
    params = sensors.make_params(config, hfov_deg=hfov, **kw)
    return float(sensors.camera_p_detect(scene, params, config, temperature=temperature)[0, vehicle])


def test_pixels_per_radian_and_the_depth_noise_by_hand():
    k = float(sensors.camera_px_per_rad(CAMERA.params))
    assert k == pytest.approx(1280 / math.radians(30)) and abs(k - 2400) / 2400 < 0.03  # Table II's 2400 px
    # Z = 50 m at 30 deg (k = 2444.62 px/rad): 2500 * 0.5 / 293.354 = 4.26106 m; at 120 deg k is 4x smaller.
    z = jnp.asarray([10.0, 50.0])
    sigma = np.asarray(sensors.camera_depth_sigma_m(z, CAMERA.params, CAMERA))
    np.testing.assert_allclose(sigma, np.asarray(z) ** 2 * 0.5 / (k * 0.12), rtol=1e-12)
    assert sigma[1] == pytest.approx(4.26106, rel=1e-5)
    wide = sensors.make_params(CAMERA, hfov_deg=120.0)
    assert float(sensors.camera_px_per_rad(wide)) == pytest.approx(611.155, rel=1e-5)
    assert float(sensors.camera_depth_sigma_m(jnp.asarray(50.0), wide, CAMERA)) == pytest.approx(17.0442, rel=1e-5)


@pytest.mark.parametrize("hfov", [30, 30.0])
def test_the_paper_accuracy_is_table_iis_focal_length_at_any_hfov(hfov):
    # accuracy_follows_hfov off: sigma_Z(50 m) = 2500 * 0.5 / (2400 * 0.12) = 4.340278 m at every HFOV
    # (with the lens's k at 120 deg it would be 17.0442 m); an integer HFOV keeps it a float.
    paper = cfg.replace(CAMERA, accuracy_follows_hfov=False)
    for h in (30.0, 120.0):
        sigma = float(sensors.camera_depth_sigma_m(jnp.asarray(50.0), sensors.make_params(paper, hfov_deg=h), paper))
        assert sigma == pytest.approx(4.340278, rel=1e-6)
    odd = cfg.replace(paper, focal_length_px=2400.5)
    assert float(sensors.camera_accuracy_px_per_rad(dataclasses.replace(CAMERA.params, hfov_deg=hfov), odd)) == 2400.5


def test_the_paper_accuracy_keeps_float32():
    paper = sensors.load_config("camera", profile="paper")
    params32 = jax.tree.map(jnp.float32, sensors.make_params(paper, hfov_deg=120.0))
    k = sensors.camera_accuracy_px_per_rad(params32, paper)
    assert k.dtype == jnp.float32 and float(k) == paper.focal_length_px
    # a float32 scene and parameters: one bearing sigma is 0.5 px / 2400 px/rad, measured in float32
    scene32 = make_scene([[0.0, paper.mount_x_m + 50.0]], [[0.0, 0.0]], dtype=np.float32)
    draws = jnp.zeros((2, 1, 2), jnp.float32).at[1, 0, 1].set(1.0)
    det = sensors.detect(scene32, params32, paper, draws)
    assert det.x_m.dtype == np.float32
    assert float(jnp.arctan2(det.y_m[0, 1], det.x_m[0, 1] - paper.mount_x_m)) == pytest.approx(0.5 / 2400, rel=1e-4)


# R_max = 0.9 / tan(5 / k):  30 deg, 1280 px: k = 2444.62, 440.03 m; 120 deg: 110.005 m;
# 180 deg: 73.335 m; 3840 px at 120 deg: 330.02 m, at 180 deg: 220.015 m.
@pytest.mark.parametrize("hfov, width, r_max", [
    (30.0, 1280.0, 440.03), (120.0, 1280.0, 110.005), (180.0, 1280.0, 73.335),
    (120.0, 3840.0, 330.02), (180.0, 3840.0, 220.015),
])
def test_a_car_resolves_out_to_where_it_is_10_px_wide(hfov, width, r_max):
    params = sensors.make_params(CAMERA, hfov_deg=hfov, width_px=width, range_m=1000.0)
    hard = np.asarray(jit_p_detect(ahead(CAMERA, r_max * np.array([0.99, 0.998, 1.002, 1.01])), params, CAMERA,
                                   mode="hard"))[:, 1]
    np.testing.assert_array_equal(hard, [1, 1, 0, 0])
    # Soft, exactly at R_max: the width gate sigmoid(0) = 1/2, the visible gate sigmoid(0.4 / 0.05) = 0.999665.
    assert float(jit_p_detect(ahead(CAMERA, [r_max]), params, CAMERA)[0, 1]) == pytest.approx(0.5 * 0.999665, abs=2e-4)


def test_the_range_limits_at_120_deg_and_the_resolution_at_180_deg():
    scene = ahead(CAMERA, [54.0, 56.0, 73.0, 74.0, 99.5, 100.5])
    det = {h: np.asarray(jit_p_detect(scene, sensors.make_params(CAMERA, hfov_deg=h), CAMERA, mode="hard"))[:, 1]
           for h in (120.0, 180.0)}
    np.testing.assert_array_equal(det[120.0], [1, 1, 1, 1, 1, 0])  # the 100 m range decides
    np.testing.assert_array_equal(det[180.0], [1, 1, 1, 0, 0, 0])  # 73.3 m of resolvability decides


def test_the_fov_edge_is_half_the_hfov():
    scene = ahead(CAMERA, [30.0] * 4, [29.0, 31.0, 59.0, 61.0])
    seen = {h: np.asarray(jit_p_detect(scene, sensors.make_params(CAMERA, hfov_deg=h), CAMERA, mode="hard"))[:, 1]
            for h in (60.0, 120.0)}
    np.testing.assert_array_equal(seen[60.0], [1, 0, 0, 0])
    np.testing.assert_array_equal(seen[120.0], [1, 1, 1, 0])


def test_partial_occlusion_around_the_0_6_visible_fraction():
    scene = occlusion_scene(CAMERA.mount_x_m)
    params = sensors.make_params(CAMERA, hfov_deg=60.0)
    margin = np.asarray(hard_gates(scene, params, CAMERA)[3][0])[2]
    np.testing.assert_allclose(margin, 1.0 - np.array(COVERED) - 0.6, atol=1e-6)
    hard = np.asarray(jit_p_detect(scene, params, CAMERA, mode="hard"))
    np.testing.assert_array_equal(hard[:, 2], [1, 1, 0, 0])
    np.testing.assert_array_equal(hard[:, 1], 1)  # the occluder itself is in clear view
    # Soft: sigmoid((0.4 - covered) / 0.05) = 0.900, 0.550, 0.450, 0.022 (the soft overlap ramp
    # moves the covered fraction by < 0.003).
    soft = np.asarray(jit_p_detect(scene, params, CAMERA))[:, 2]
    np.testing.assert_allclose(soft, [0.900, 0.550, 0.450, 0.022], atol=0.01)
    # A car right behind a truck is hidden; one lane over it is not; padding never is.
    scene = make_scene([[0.0, 20.0, 40.0, 40.0, 0.0]], [[0.0, 0.0, 0.0, 3.7, 0.0]],
                       length_m=[4.5, 12.0, 4.5, 4.5, 4.5], width_m=[1.8, 2.5, 1.8, 1.8, 1.8],
                       kind=[CAR, TRUCK, CAR, CAR, CAR], present=[True] * 4 + [False])
    assert np.asarray(jit_p_detect(scene, params, CAMERA, mode="hard"))[0].tolist() == [1, 1, 0, 1, 0]


def test_a_camera_may_ask_for_the_whole_car_visible():
    whole = dataclasses.replace(CAMERA, min_visible_fraction=1.0)  # a lone car: margin 1 - 1 = 0, seen
    assert np.asarray(jit_p_detect(make_scene([[0.0, 20.0]], [[0.0, 0.0]]), whole.params, whole,
                                   mode="hard")).tolist() == [[1.0, 1.0]]


# At T = 2 the gates' temperatures are 1 deg, 3.6 m, 2 px and 0.1; divided by T (0.25 deg, 0.9 m,
# 0.5 px, 0.025) each p below moves by > 1e-2.
#  range: HFOV 30, car 100.9 m ahead: range margin -0.9 m; width 43.6 px, FOV margin 15 deg (both ~1).
#  fov: HFOV 30, car 30 m away at 15.3 deg: FOV margin -0.3 deg.
#  width: HFOV 180, car 72 m ahead: k = 407.437 px/rad, width 10.18534 px; range margin 28 m.
CASES_T2 = {
    "range": (ahead(CAMERA, [100.9]), 30.0, lambda t: sigmoid(-0.9 / (1.8 * t)) * sigmoid(0.4 / (0.05 * t))),
    "fov": (ahead(CAMERA, [30.0], [15.3]), 30.0, lambda t: sigmoid(-0.3 / (0.5 * t)) * sigmoid(0.4 / (0.05 * t))),
    "width": (ahead(CAMERA, [72.0]), 180.0,
              lambda t: (sigmoid((width_px(1280 / math.pi, 72.0) - 10.0) / t) * sigmoid(0.4 / (0.05 * t))
                         * sigmoid(28.0 / (1.8 * t)))),
}


@pytest.mark.parametrize("case", list(CASES_T2))
def test_soft_p_at_temperature_2_by_hand(case):
    scene, hfov, hand = CASES_T2[case]
    got = p(scene, hfov, temperature=2.0)
    assert got == pytest.approx(hand(2.0), rel=2e-6)
    assert abs(hand(0.5) - got) > 1e-2


def test_the_visible_gate_at_temperature_2_by_hand():
    # A car 50 m ahead at 30 deg: sigmoid(0.4 / 0.1) (divided by T: sigmoid(16) = 1 - 1e-7), times
    # the range gate sigmoid(50 / 3.6), the FOV gate sigmoid(15 / 1) and the width gate (88 px: 1 - 1e-17).
    assert p(ahead(CAMERA, [50.0]), 30.0, temperature=2.0) == pytest.approx(
        sigmoid(4.0) * sigmoid(50 / 3.6) * sigmoid(15.0), rel=1e-9)


def _occluded():
    """An occluder 38 m ahead of the camera, 1.6 m to the left, two near-temperatures nearer
    than a car 40 m ahead, covering part of it."""
    return make_scene([[0.0, CAMERA.mount_x_m + 38.0, CAMERA.mount_x_m + 40.0]], [[0.0, 1.6, 0.0]])


@pytest.mark.parametrize("temperature", [2.0, 0.5])
def test_temperature_multiplies_every_soft_temperature_occlusion_included(temperature):
    # the visible gate carries the soft occlusion; it moves by > 0.01 between temperatures 2 and 1/2
    assert_temperature_scales_the_config(_camera_terms, Tracks.of(_occluded()), CAMERA, temperature, gate=3,
                                         vehicle=2, least=0.01)


def test_the_confidence_law_scales_the_mean_by_the_unhidden_fraction():
    # The hidden fraction h of the car 40 m ahead is 0.4 minus the threshold law's visible margin
    # (hard geometry); the mean is 0.95 * size * (1 - h), size = sigmoid((110.0 px - 10) / 2) = 1 - 2e-22,
    # and p = Phi((mean - 0.6) / 0.1) times P(40 + N(0, sigma_Z) <= 100) = 1.
    hidden = 0.4 - float(hard_gates(_occluded(), CAMERA.params, CAMERA)[3][0][2, 0])
    assert 0.1 < hidden < 0.5, hidden
    params = sensors.make_params(CONFIDENCE, hfov_deg=30.0)
    got = float(sensors.camera_p_detect(_occluded(), params, CONFIDENCE, mode="hard")[0, 2])
    assert got == pytest.approx(phi((0.95 * (1.0 - hidden) - 0.6) / 0.1), rel=1e-6)


def test_the_confidence_law_reads_the_cars_width_in_pixels():
    # HFOV 180 deg, a car 72 m ahead 10.18539 px wide: size = sigmoid(0.18539 / 2) = 0.52316,
    # P(confidence >= 0.6) = Phi((0.95 size - 0.6) / 0.1) = 0.15150; sigma_Z = 53.014 m and
    # P(72 + N(0, sigma_Z) <= 100) = 0.70131. (Read as 3 atan(0.9 / 72) wide, p would be 0.700.)
    k = 1280.0 / math.pi
    confidence = phi((0.95 * sigmoid((width_px(k, 72.0) - 10.0) / 2.0) - 0.6) / 0.1)
    in_range = phi(28.0 / math.hypot(72.0**2 * 0.5 / (k * 0.12), 1e-3))
    assert confidence == pytest.approx(0.15150, abs=1e-5) and in_range == pytest.approx(0.70131, abs=1e-5)
    got = float(sensors.camera_p_detect(ahead(CAMERA, [72.0]), sensors.make_params(CONFIDENCE, hfov_deg=180.0),
                                        CONFIDENCE, mode="hard")[0, 1])
    assert got == pytest.approx(confidence * in_range, rel=1e-5)  # float32's 1e-7 on the width: 2e-6 in p
