"""The measurements of `detect`: measured = true + sigma * draw along and across the line of sight,
back in the world with the ego's pose; common random numbers (the draws fixed by the key, only
their scale depends on r); the draws' statistics, shapes and types; batches of scenes."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _laws import threshold_config
from _sensor_scenes import ahead, jit_detect, jit_p_detect, make_scene, traffic_scene

from diffsense import config as cfg
from diffsense import sensors

RADAR = threshold_config("radar")
CAMERA = threshold_config("camera")
KEY = jax.random.key(11, impl="rbg")  # threefry compiles ~3 s slower on CPU
DRAWS = 4000  # frames of one static geometry: one (range, azimuth) draw pair each


def assert_gaussian(errors, sigma):
    """Mean within 3 standard errors of 0, std within 3 standard errors (sigma / sqrt(2 (n - 1)))."""
    n = errors.size
    assert abs(errors.mean()) <= 3 * sigma / math.sqrt(n)
    assert abs(errors.std(ddof=1) - sigma) <= 3 * sigma / math.sqrt(2 * (n - 1))


# Radar: 0.400067 m and 0.100212 deg at 20 m, 0.845172 m and 0.669311 deg at 200 m (tests/test_radar.py).
# Camera (30 deg, k = 2444.62 px/rad) at 30 m: depth 900 * 0.5 / (k * 0.12) = 1.533981 m, bearing
# 0.5 px / k = 2.04531e-4 rad; at 120 deg both are 4x larger.
@pytest.mark.parametrize("name, hfov, range_m, sigma_r, sigma_az_deg", [
    ("radar", 30.0, 20.0, 0.400067, 0.100212),
    ("radar", 30.0, 200.0, 0.845172, 0.669311),
    ("camera", 30.0, 30.0, 1.533981, math.degrees(2.04531e-4)),
    ("camera", 120.0, 30.0, 4 * 1.533981, math.degrees(4 * 2.04531e-4)),
])
def test_measurement_errors_have_the_noise_scales_and_are_independent(name, hfov, range_m, sigma_r, sigma_az_deg):
    config = RADAR if name == "radar" else CAMERA
    det = jit_detect(ahead(config, np.full(DRAWS, range_m)), sensors.make_params(config, hfov_deg=hfov), config, KEY)
    dx, dy = np.asarray(det.x_m)[:, 1] - config.mount_x_m, np.asarray(det.y_m)[:, 1]
    range_err, az_err = np.hypot(dx, dy) - range_m, np.arctan2(dy, dx)
    assert_gaussian(range_err, sigma_r)
    assert_gaussian(az_err, math.radians(sigma_az_deg))  # turned by 2 atan(e / 2): < 4e-5 relative here
    assert abs(np.corrcoef(range_err, az_err)[0, 1]) <= 3 / math.sqrt(DRAWS)


def test_the_draws_are_standard_normal_and_independent():
    draws = np.asarray(sensors.measurement_noise(KEY, ahead(RADAR, np.full(DRAWS, 50.0))))
    assert draws.shape == (2, DRAWS, 2)
    for d in draws[..., 1]:
        assert_gaussian(d, 1.0)
    assert abs(np.corrcoef(draws[0, :, 1], draws[1, :, 1])[0, 1]) <= 3 / math.sqrt(DRAWS)


def test_the_measured_range_is_true_plus_sigma_times_the_draw():
    # Camera at 30 deg, a car 30 m ahead: sigma_Z = 1.533981 m. Draws (range, azimuth) = (+1, 0):
    # measured 31.533981 m straight ahead; (-2, 0): 26.932038 m.
    draws = jnp.zeros((2, 2, 2)).at[0, :, 1].set(jnp.array([1.0, -2.0]))
    det = jit_detect(ahead(CAMERA, [30.0, 30.0]), CAMERA.params, CAMERA, draws)
    np.testing.assert_allclose(np.asarray(det.x_m)[:, 1] - CAMERA.mount_x_m, [31.533981, 26.932038], atol=1e-6)
    np.testing.assert_allclose(np.asarray(det.y_m)[:, 1], 0.0, atol=1e-12)


def _noise_free(config):
    return cfg.replace(config, disparity_error_px=0.0, bearing_error_px=0.0)


def test_measurements_return_to_the_world_with_the_ego_pose():
    # Ego rotated by 30 deg at (5, -2); targets placed in the ego frame, converted to the world.
    yaw = math.radians(30)
    rel = np.array([[0.0, 0.0], [40.0, 3.0], [25.0, -6.0]])
    c, s = math.cos(yaw), math.sin(yaw)
    scene = make_scene((5.0 + c * rel[:, 0] - s * rel[:, 1])[None], (-2.0 + s * rel[:, 0] + c * rel[:, 1])[None],
                       heading_rad=yaw)
    config = _noise_free(CAMERA)
    params = sensors.make_params(config, hfov_deg=90.0)
    det = jit_detect(scene, params, config, KEY)
    np.testing.assert_allclose(det.x_m, scene.x_m, atol=1e-9)
    np.testing.assert_allclose(det.y_m, scene.y_m, atol=1e-9)
    np.testing.assert_array_equal(jit_p_detect(scene, params, config, mode="hard"), [[1.0, 1.0, 1.0]])


def test_a_vehicle_at_the_sensor_or_beside_it_is_measured_where_it_is():
    config = _noise_free(CAMERA)  # vehicle 1 exactly at the sensor, vehicle 2 half a metre to its left
    x = [[0.0, config.mount_x_m, config.mount_x_m]]
    scene = make_scene(x, [[0.0, 0.0, 0.5]], length_m=[4.5, 0.2, 0.2], width_m=[1.8, 0.2, 0.2])
    det = jit_detect(scene, config.params, config, KEY)
    np.testing.assert_allclose(np.asarray(det.x_m), np.asarray(scene.x_m), atol=1e-12)
    np.testing.assert_allclose(np.asarray(det.y_m), np.asarray(scene.y_m), atol=1e-12)


def test_common_random_numbers_only_the_scale_depends_on_r():
    scene = traffic_scene(num_frames=5)
    config = cfg.replace(CAMERA, bearing_error_px=0.0)
    errors = []
    for hfov in (30.0, 60.0):
        det = jit_detect(scene, sensors.make_params(config, hfov_deg=hfov), config, KEY)
        sx = scene.x_m[:, :1] + config.mount_x_m
        measured = np.hypot(det.x_m - sx, det.y_m - scene.y_m[:, :1])
        errors.append((measured - np.hypot(scene.x_m - sx, scene.y_m - scene.y_m[:, :1]))[:, 1:-1])
    np.testing.assert_allclose(errors[1], 2 * errors[0], rtol=1e-9)  # sigma_Z ~ 1 / k = HFOV / width
    first, again = (jit_detect(scene, config.params, config, KEY) for _ in range(2))
    np.testing.assert_array_equal(again.x_m, first.x_m)
    other = jit_detect(scene, config.params, config, jax.random.key(8, impl="rbg"))
    assert not np.allclose(other.x_m[:, 1:-1], first.x_m[:, 1:-1])


def test_the_draws_are_one_pair_per_frame_and_vehicle_in_the_scenes_type():
    one = make_scene([[0.0, 40.0]] * 3, [[0.0, 2.0]] * 3)
    batch = jax.tree.map(lambda a: jnp.stack([a] * 4), one)
    draws = sensors.measurement_noise(KEY, one)
    assert draws.shape == (2, 3, 2) and sensors.measurement_noise(KEY, batch).shape == (4, 2, 3, 2)
    by_key, by_draws = jit_detect(one, CAMERA.params, CAMERA, KEY), jit_detect(one, CAMERA.params, CAMERA, draws)
    np.testing.assert_array_equal(np.asarray(by_key.x_m), np.asarray(by_draws.x_m))
    np.testing.assert_array_equal(np.asarray(by_key.y_m), np.asarray(by_draws.y_m))
    one32 = make_scene([[0.0, 40.0]] * 3, [[0.0, 2.0]] * 3, dtype=np.float32)
    assert sensors.measurement_noise(KEY, one32).dtype == np.float32
    assert sensors.measurement_noise(KEY, jax.tree.map(lambda a: jnp.stack([a, a]), one32)).dtype == np.float32
    for given in (jnp.ones((2, 3, 2), jnp.float32), jnp.ones((2, 3, 2), jnp.float64)):  # cast to the scene's
        det = jit_detect(one32, CAMERA.params, CAMERA, given)
        assert det.x_m.dtype == np.float32 and det.p_detect.dtype == np.float32


def test_detect_batch_is_detect_per_scene_with_its_own_draws():
    one = traffic_scene(num_frames=4)
    scenes = jax.tree.map(lambda a: jnp.stack([a, a]), one)
    batch_detect = jax.jit(sensors.detect_batch, static_argnames=("config", "mode"))
    batch = batch_detect(scenes, RADAR.params, RADAR, KEY)
    assert batch.p_detect.shape == (2, *one.x_m.shape)
    noise = jax.jit(sensors.measurement_noise)(KEY, scenes)
    for a, b in zip(jax.tree.leaves(batch_detect(scenes, RADAR.params, RADAR, noise)), jax.tree.leaves(batch)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-12, atol=1e-12)
    for n in range(2):
        single = jit_detect(one, RADAR.params, RADAR, noise[n])
        for a, b in zip(jax.tree.leaves(jax.tree.map(lambda a: a[n], batch)), jax.tree.leaves(single)):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-12, atol=1e-12)
    # float32 draws under x64 are draws too, used as given, not taken for a key
    noise32 = noise.astype(jnp.float32)
    np.testing.assert_array_equal(batch_detect(scenes, RADAR.params, RADAR, noise32).x_m,
                                  batch_detect(scenes, RADAR.params, RADAR, noise32.astype(noise.dtype)).x_m)
    # different draws per scene: different noise, same probabilities
    np.testing.assert_array_equal(batch.p_detect[0], batch.p_detect[1])
    assert not np.allclose(batch.x_m[0, :, 1:-1], batch.x_m[1, :, 1:-1])


@pytest.mark.slow  # two threefry compiles: ~5-15 s on the shared 2-core machine
def test_batch_noise_of_threefry_keys_is_the_folded_single_scene_noise():
    # (rbg keys do not promise the same draws batched and unbatched)
    key, one = jax.random.key(11), traffic_scene(num_frames=4)
    scenes = jax.tree.map(lambda a: jnp.stack([a, a]), one)
    draw = jax.jit(sensors.measurement_noise)
    np.testing.assert_array_equal(draw(key, scenes)[1], draw(jax.random.fold_in(key, 1), one))
