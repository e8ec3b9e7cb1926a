"""A problem's setup as a few whole programs and host arrays: the same bits as op by op. Building
E(r) derives its random keys and draws in single compiled programs (kept on disk, so a warm run
neither traces nor lowers them) and converts the scenario's constants in numpy. Each is checked
against the JAX operations it replaces, bit for bit, in float64 and float32.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.config import replace
from diffsense.metrics._build import _scenario_keys, _variant_draws
from diffsense.metrics._estimators import mc_uniforms
from diffsense.runtime import call, keep_in
from diffsense.scene import (
    lane_centre_d_m,
    load_road,
    load_scenario,
    load_vehicle_models,
)
from diffsense.scene._variants import scenario_numbers
from diffsense.study import seed_keys


def _bits(key) -> np.ndarray:
    return np.asarray(jax.random.key_data(key) if jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key) else key)


@pytest.fixture(params=["in memory", "kept on disk"])
def where(request, tmp_path):
    """Run `call` as the library does (no folder) and as the command line does (a folder)."""
    keep_in(tmp_path / "executables" if request.param == "kept on disk" else None)
    yield request.param
    keep_in(None)


@pytest.mark.parametrize("seed", [0, 1, 12345, 2**31 + 5])
def test_seed_keys_are_split_of_prngkey(seed, where):
    scene_key, noise_key = seed_keys(seed)
    expected = jax.random.split(jax.random.PRNGKey(seed))
    np.testing.assert_array_equal(_bits(scene_key), _bits(expected[0]))
    np.testing.assert_array_equal(_bits(noise_key), _bits(expected[1]))
    assert not np.array_equal(_bits(scene_key), _bits(noise_key))


def test_scenario_keys_are_fold_in_of_each_index(where):
    key = jax.random.PRNGKey(7)
    keys = call(_scenario_keys, key, 4)
    assert len(keys) == 4
    for i, k in enumerate(keys):
        np.testing.assert_array_equal(_bits(k), _bits(jax.random.fold_in(key, i)))


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_variant_draws_are_the_op_by_op_draws(dtype, where):
    key, n, samples, shape = jax.random.PRNGKey(3), 3, 4, (5, 2)
    noise_keys, uniform = call(_variant_draws, key, n, samples, shape, dtype)
    noise_key, mc_key = jax.random.split(key)
    np.testing.assert_array_equal(_bits(noise_keys), _bits(jax.random.split(noise_key, n)))
    expected = jnp.stack([mc_uniforms(k, samples, shape, jnp.dtype(dtype)) for k in jax.random.split(mc_key, n)])
    assert uniform.dtype == jnp.dtype(dtype) and uniform.shape == (n, samples, *shape)
    np.testing.assert_array_equal(np.asarray(uniform), np.asarray(expected))
    assert 0.0 < float(uniform.min()) and float(uniform.max()) < 1.0


def test_no_monte_carlo_draws_is_an_empty_array(where):
    _, uniform = call(_variant_draws, jax.random.PRNGKey(0), 2, 0, (3, 4), "float64")
    assert uniform.shape == (2, 0, 3, 4)


@pytest.mark.parametrize(("dtype", "x64"), [(jnp.float64, True), (jnp.float32, True), (jnp.float32, False)],
                         ids=["float64", "float32", "float32-without-x64"])
@pytest.mark.parametrize("width_m", [None, 3.7, 3.3])
def test_lane_offsets_in_numpy_equal_lane_centre_d_m(dtype, width_m, x64):
    """3.7 and 3.3 m are not binary fractions: the product rounds, and must round as JAX does,
    in float64 with x64 on and in float32 with it off (a float32 problem in a float32 process)."""
    with jax.enable_x64(x64):
        _check_lane_offsets(dtype, width_m)


def _check_lane_offsets(dtype, width_m):
    cfg = load_scenario("sc05")
    cfg = replace(cfg, background=replace(cfg.background, count=7))  # background_d_m has entries
    road, models = load_road(cfg.road), load_vehicle_models()
    if width_m is not None:
        road = dataclasses.replace(road, lane_width_m=np.float64(width_m))
    nums = scenario_numbers(cfg, models, road, dtype)
    lanes = np.array([cfg.ego.lane, cfg.target_lane, cfg.ego.lane, cfg.target_lane, cfg.adjacent_lane])
    np.testing.assert_array_equal(np.asarray(nums.d_m), np.asarray(jnp.asarray(lane_centre_d_m(road, lanes), dtype)))
    assert nums.d_m.dtype == jnp.dtype(dtype)
    bg_lanes = np.arange(cfg.background.count) % int(road.num_lanes)
    np.testing.assert_array_equal(np.asarray(nums.background_d_m),
                                  np.asarray(jnp.asarray(lane_centre_d_m(road, bg_lanes), dtype)))
    # (lane + 1/2) x width, by hand
    np.testing.assert_allclose(np.asarray(nums.d_m, np.float64), (lanes + 0.5) * float(road.lane_width_m),
                               rtol=1e-6 if dtype == jnp.float32 else 1e-15)
    if not jax.config.jax_enable_x64 and width_m is not None:  # JAX rounds the width to float32 first
        width32 = np.float32(width_m)
        np.testing.assert_array_equal(np.asarray(nums.d_m), (lanes + 0.5).astype(np.float32) * width32)


def test_lane_offsets_of_a_traced_road_stay_traced():
    cfg = load_scenario("sc01")
    road, models = load_road(cfg.road), load_vehicle_models()

    def d_m(width):
        return scenario_numbers(cfg, models, dataclasses.replace(road, lane_width_m=width), jnp.float64).d_m

    lanes = np.array([cfg.ego.lane, cfg.target_lane, cfg.ego.lane, cfg.target_lane, cfg.adjacent_lane])
    np.testing.assert_array_equal(np.asarray(jax.jit(d_m)(3.6)), (lanes + 0.5) * 3.6)
    np.testing.assert_array_equal(np.asarray(jax.grad(lambda w: d_m(w).sum())(3.6)), np.sum(lanes + 0.5))
