"""Every public function of diffsense.sensors under jit; batches; dtype following."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_sensor_scenes import traffic_scene

from diffsense import sensors as sensor
from diffsense.runtime._errors import InputError
from diffsense.scene import CAR, TRUCK

KEY = jax.random.key(11, impl="rbg")  # threefry compiles ~3 s slower on CPU
RADAR = sensor.load_config("radar")
CAMERA = sensor.load_config("camera")
STATIC = ("config", "mode")


def _same(a, b):
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-12, atol=1e-12)


def test_detect_dispatches_and_agrees_with_the_sensor_functions_under_jit():
    scene = traffic_scene(num_frames=4)
    for config, own_detect, own_p in ((RADAR, sensor.radar_detect, sensor.radar_p_detect),
                                      (CAMERA, sensor.camera_detect, sensor.camera_p_detect)):
        def all_four(s, p, t, config):
            return [(sensor.detect(s, p, config, KEY, mode=mode, temperature=t),
                     own_detect(s, p, config, KEY, mode=mode, temperature=t),
                     sensor.p_detect(s, p, config, mode=mode, temperature=t),
                     own_p(s, p, config, mode=mode, temperature=t)) for mode in sensor.MODES]
        results = jax.jit(all_four, static_argnames="config")(scene, config.params, 0.5, config=config)
        for det, own, p, p_own in results:
            _same(det, own)
            _same(det.p_detect, p)
            _same(p, p_own)
        soft, hard = (r[2] for r in results)
        assert set(np.unique(hard)) == {0.0, 1.0}
        assert np.any((soft > 0) & (soft < 1))


def test_detect_batch_is_detect_per_scene_with_the_drawn_noise():
    one = traffic_scene(num_frames=4)
    scenes = jax.tree.map(lambda a: jnp.stack([a, a]), one)
    batch_detect = jax.jit(sensor.detect_batch, static_argnames=STATIC)
    batch = batch_detect(scenes, RADAR.params, RADAR, KEY)
    assert batch.p_detect.shape == (2, *one.x_m.shape)
    noise = jax.jit(sensor.measurement_noise)(KEY, scenes)
    assert noise.shape == (2, 2, *one.x_m.shape)
    _same(batch_detect(scenes, RADAR.params, RADAR, noise), batch)
    # float32 draws under x64 are draws too, used as given, not taken for a key
    noise32 = noise.astype(jnp.float32)
    _same(batch_detect(scenes, RADAR.params, RADAR, noise32),
          batch_detect(scenes, RADAR.params, RADAR, noise32.astype(noise.dtype)))
    single = jax.jit(sensor.detect, static_argnames=STATIC)
    for n in range(2):
        _same(jax.tree.map(lambda a: a[n], batch), single(one, RADAR.params, RADAR, noise[n]))
    # different draws per scene: different noise, same probabilities
    _same(batch.p_detect[0], batch.p_detect[1])
    assert not np.allclose(batch.x_m[0, :, 1:-1], batch.x_m[1, :, 1:-1])


@pytest.mark.slow  # two threefry compiles: ~5-15 s on the shared 2-core machine
def test_batch_noise_of_threefry_keys_is_the_folded_single_scene_noise():
    # (rbg keys do not promise the same draws batched and unbatched)
    key = jax.random.key(11)
    one = traffic_scene(num_frames=4)
    scenes = jax.tree.map(lambda a: jnp.stack([a, a]), one)
    draw = jax.jit(sensor.measurement_noise)
    np.testing.assert_array_equal(draw(key, scenes)[1], draw(jax.random.fold_in(key, 1), one))


def test_noise_and_scene_shapes_are_checked():
    one = traffic_scene(num_frames=4)
    with pytest.raises(InputError, match="measurement noise has shape"):
        sensor.detect(one, RADAR.params, RADAR, jnp.zeros((2, 3, 8)))
    scenes = jax.tree.map(lambda a: jnp.stack([a, a]), one)
    with pytest.raises(InputError, match="use detect_batch"):
        sensor.p_detect(scenes, RADAR.params, RADAR)
    with pytest.raises(InputError, match="unknown detection mode 'fuzzy'"):
        sensor.p_detect(one, RADAR.params, RADAR, mode="fuzzy")
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(InputError, match="temperature must be a positive number"):
            sensor.p_detect(one, RADAR.params, RADAR, temperature=bad)


def test_physics_helpers_under_jit():
    ranges = jnp.asarray([10.0, 100.0])
    f = jax.jit(lambda r, p, config: (sensor.radar_snr_db(r, 10.0, p, config),
                                      sensor.radar_gain_dbi(p, config),
                                      sensor.radar_rcs_dbsm(jnp.asarray([CAR, TRUCK]), config)),
                static_argnames="config")
    snr, gain, rcs = f(ranges, RADAR.params, config=RADAR)
    assert float(snr[0] - snr[1]) == pytest.approx(40.0 + 2 * 0.4 * 0.09, abs=1e-9)
    assert float(gain) == pytest.approx(17.404, abs=1e-3)
    np.testing.assert_array_equal(rcs, [10.0, 20.0])
    g = jax.jit(lambda r, p, config: (sensor.camera_px_per_rad(p),
                                      sensor.camera_depth_sigma_m(r, p, config)),
                static_argnames="config")
    k, sigma = g(ranges, CAMERA.params, config=CAMERA)
    np.testing.assert_allclose(sigma, np.asarray(ranges) ** 2 * 0.5 / (float(k) * 0.12))


def test_parameter_helpers_under_jit():
    # with_param and check_params take traced values (checks apply to concrete values only)
    f = jax.jit(lambda h: sensor.radar_gain_dbi(
        sensor.check_params(sensor.with_param(RADAR.params, "hfov_deg", h)), RADAR))
    assert float(f(30.0)) - float(f(60.0)) == pytest.approx(3.0103, abs=1e-4)
    grad = jax.jit(jax.grad(lambda h: sensor.radar_gain_dbi(
        sensor.with_param(RADAR.params, "hfov_deg", h), RADAR)))(30.0)
    assert float(grad) == pytest.approx(-10 / (30.0 * np.log(10)), rel=1e-9)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_outputs_follow_the_scene_dtype(dtype):
    scene = traffic_scene(num_frames=4, dtype=dtype)
    det = jax.jit(sensor.detect, static_argnames=STATIC)(scene, CAMERA.params, CAMERA, KEY)
    assert {leaf.dtype for leaf in jax.tree.leaves(det)} == {np.dtype(dtype)}
