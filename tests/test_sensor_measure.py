"""The measurement chain of `detect`, pinned (from the sensors' mutation survivors): how the
draws enter (measured = true + sigma * draw), their dtype, a vehicle at the sensor itself,
input checks, and hard mode all the way down to the occlusion comparisons."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_sensor_scenes import make_scene

from diffsense import config as cfg
from diffsense import sensors as sensor
from diffsense.runtime._errors import InputError

CAMERA = sensor.load_config("camera")
RADAR = sensor.load_config("radar")
KEY = jax.random.key(2, impl="rbg")
detect = jax.jit(sensor.detect, static_argnames=("config", "mode"))


def test_measured_range_is_true_plus_sigma_times_the_draw():
    # Camera at 30 deg, a car 30 m ahead: sigma_Z = 900 * 0.5 / (2444.62 * 0.12) = 1.533981 m.
    # Draws (range, azimuth) = (+1, 0): measured 31.533981 m straight ahead; (-2, 0): 26.932038.
    scene = make_scene([[0.0, CAMERA.mount_x_m + 30.0]] * 2, [[0.0, 0.0]] * 2)
    draws = jnp.zeros((2, 2, 2)).at[0, :, 1].set(jnp.array([1.0, -2.0]))
    det = detect(scene, CAMERA.params, CAMERA, draws)
    np.testing.assert_allclose(np.asarray(det.x_m)[:, 1] - CAMERA.mount_x_m, [31.533981, 26.932038],
                               atol=1e-6)
    np.testing.assert_allclose(np.asarray(det.y_m)[:, 1], 0.0, atol=1e-12)


def test_draws_have_the_scene_dtype_and_float32_draws_are_accepted():
    one = make_scene([[0.0, 40.0]] * 3, [[0.0, 2.0]] * 3, dtype=np.float32)
    batch = jax.tree.map(lambda a: jnp.stack([a, a]), one)
    assert sensor.measurement_noise(KEY, one).dtype == np.float32
    assert sensor.measurement_noise(KEY, batch).dtype == np.float32
    for draws in (jnp.ones((2, 3, 2), jnp.float32), jnp.ones((2, 3, 2), jnp.float64)):
        det = detect(one, CAMERA.params, CAMERA, draws)  # float64 draws are cast to the scene's
        assert det.x_m.dtype == np.float32 and det.p_detect.dtype == np.float32


def test_a_vehicle_at_the_sensor_or_beside_it_is_measured_where_it_is():
    # Noise-free camera: vehicle 1 sits exactly at the sensor, vehicle 2 half a metre to its left.
    config = cfg.replace(CAMERA, disparity_error_px=0.0, bearing_error_px=0.0)
    x = [[0.0, config.mount_x_m, config.mount_x_m]]
    scene = make_scene(x, [[0.0, 0.0, 0.5]], length_m=[4.5, 0.2, 0.2], width_m=[1.8, 0.2, 0.2])
    det = detect(scene, config.params, config, KEY)
    np.testing.assert_allclose(np.asarray(det.x_m), np.asarray(scene.x_m), atol=1e-12)
    np.testing.assert_allclose(np.asarray(det.y_m), np.asarray(scene.y_m), atol=1e-12)


def test_detect_checks_its_temperature_like_p_detect():
    scene = make_scene([[0.0, 40.0]], [[0.0, 0.0]])
    for bad in (0.0, -1.0):
        with pytest.raises(InputError, match="temperature must be a positive number"):
            sensor.detect(scene, CAMERA.params, CAMERA, KEY, temperature=bad)


@pytest.mark.parametrize("config", [CAMERA, RADAR], ids=["camera", "radar"])
def test_hard_detect_compares_ranges_hard(config):
    # An occluder only 0.5 m nearer than the car it covers by 45 %: hard "nearer" is 1 (covered
    # 45 %: the camera misses the car; the radar loses 15 dB * 0.45), while a soft comparison
    # (sigmoid(0.5 / 1 m) = 0.62) would count only 28 %. detect's hard p must equal p_detect's.
    s0 = config.mount_x_m + 30.0
    scene = make_scene([[0.0, s0 - 0.5, s0]], [[0.0, 1.8 * 0.55, 0.0]])
    params = sensor.make_params(config, hfov_deg=60.0)
    hard = np.asarray(sensor.p_detect(scene, params, config, mode="hard"))
    np.testing.assert_array_equal(np.asarray(detect(scene, params, config, KEY, mode="hard").p_detect), hard)
    if config is CAMERA:
        assert hard[0, 2] == 0.0


def test_paper_profile_accuracy_is_table_ii_at_every_hfov():
    # accuracy_follows_hfov off (the paper profile): the accuracy uses Table II's focal length
    # 2400 px whatever the HFOV: sigma_Z(50 m) = 2500 * 0.5 / (2400 * 0.12) = 4.340278 m, bearing
    # 0.5 / 2400 rad; with the lens's k at 120 deg (611.15 px/rad) it would be 17.0442 m.
    paper = cfg.replace(CAMERA, accuracy_follows_hfov=False)
    for hfov in (30.0, 120.0):
        params = sensor.make_params(paper, hfov_deg=hfov)
        sigma = float(sensor.camera_depth_sigma_m(jnp.asarray(50.0), params, paper))
        assert sigma == pytest.approx(4.340278, rel=1e-6)
    # float32 parameters and scene: the focal length does not promote the output to float64
    params32 = jax.tree.map(lambda v: jnp.float32(v), sensor.make_params(paper, hfov_deg=120.0))
    scene32 = make_scene([[0.0, paper.mount_x_m + 50.0]], [[0.0, 0.0]], dtype=np.float32)
    draws = jnp.zeros((2, 1, 2), jnp.float32).at[1, 0, 1].set(1.0)  # one bearing sigma
    det = detect(scene32, params32, paper, draws)
    assert det.x_m.dtype == np.float32
    bearing = float(jnp.arctan2(det.y_m[0, 1], det.x_m[0, 1] - paper.mount_x_m))
    assert bearing == pytest.approx(0.5 / 2400, rel=1e-4)


@pytest.mark.parametrize("mode", ["soft", "hard"])
def test_padding_slots_hide_nothing_and_hard_output_keeps_float32(mode):
    # A padding slot (present False) parked 20 m ahead, in line with a car at 40 m.
    scene = make_scene([[0.0, 40.0, 20.0]], [[0.0, 0.0, 0.0]], present=[True, True, False],
                       dtype=np.float32)
    p = sensor.p_detect(scene, CAMERA.params, CAMERA, mode=mode)
    assert p.dtype == np.float32
    assert float(p[0, 1]) > 0.99 and float(p[0, 2]) == 0.0


def test_measurement_noise_is_one_range_and_one_azimuth_draw_per_frame_and_vehicle():
    # 3 frames, 2 vehicles: draws [2, 3, 2]; a batch of 4 scenes: [4, 2, 3, 2]. Passing the draws
    # gives what passing their key gives.
    one = make_scene([[0.0, 40.0]] * 3, [[0.0, 2.0]] * 3)
    batch = jax.tree.map(lambda a: jnp.stack([a] * 4), one)
    draws = sensor.measurement_noise(KEY, one)
    assert draws.shape == (2, 3, 2)
    assert sensor.measurement_noise(KEY, batch).shape == (4, 2, 3, 2)
    by_key, by_draws = detect(one, CAMERA.params, CAMERA, KEY), detect(one, CAMERA.params, CAMERA, draws)
    np.testing.assert_array_equal(np.asarray(by_key.x_m), np.asarray(by_draws.x_m))
    np.testing.assert_array_equal(np.asarray(by_key.y_m), np.asarray(by_draws.y_m))
