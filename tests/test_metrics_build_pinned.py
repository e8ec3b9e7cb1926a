"""The scene batches behind an objective (`diffsense/metrics/_build.py`): `with_scenes` rebuilding
the truth from other scenes, the speed-shifted re-simulation and recorded scenes, by hand.

The toy scenes drive straight along x at constant speed (tests/_synthetic.py), so the target's
true future in the road frame is speed * time ahead along s: at the predictor's j-th point,
(j + 1) * frames_per_point * 0.1 s ahead.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense import config as cfg
from diffsense import sensors as sensor
from diffsense.metrics import EstimatorConfig, make_objective, recorded_scenes, speed_shifted_scenes, with_scenes
from diffsense.predictors import CSLSTM_SPEC
from diffsense.scene import TARGET_INDEX
from diffsense.sensors._laws import RadarDetection
from diffsense.tracks import prediction_frames
from tests._recorded_files import write_highd
from tests._synthetic import straight_scene
from tests._toy_pipeline import TOY_GAIN, ToyPredictor, ToySensor, toy_objective, toy_scenes


def _future_s(E, speeds_mps):
    """The target's true future along s [n, F] for scenes whose target drives at `speeds_mps`."""
    step_s = E.spec.frames_per_point(0.1) * 0.1
    points = E.data.true_fut.shape[2]
    return np.asarray(speeds_mps)[:, None] * step_s * np.arange(1, points + 1)[None, :]


@pytest.fixture(scope="module")
def objective():
    jax.config.update("jax_enable_x64", True)
    return toy_objective(n=3, instants=2)


def test_true_future_is_the_targets_speed_times_the_time_ahead(objective):
    fut = np.asarray(objective.data.true_fut)  # [n, I, F, 2]
    for i in range(fut.shape[1]):
        np.testing.assert_allclose(fut[:, i, :, 0], _future_s(objective, [24.0, 25.0, 26.0]), atol=1e-9)


def test_with_scenes_rebuilds_the_truth_from_the_new_scenes(objective):
    # the same cars, every one 3 m/s faster: the target's future along s grows by 3 m/s
    faster = [straight_scene(s0_m=[0.0, 25.0 + 5 * k, 45.0 + 7 * k, 80.0 - 3 * k], lane=[1, 2, 2, 1],
                             speed_mps=[28.0, 27.0 + k, 27.5, 28.5], lane_change=(1, 3.0 + k, 4.0, 1))
              for k in range(3)]
    scenes = jax.tree.map(lambda *a: jnp.stack(a), *faster)
    moved = with_scenes(objective, scenes)
    fut = np.asarray(moved.data.true_fut)
    np.testing.assert_allclose(fut[:, 0, :, 0], _future_s(objective, [27.0, 28.0, 29.0]), atol=1e-9)
    np.testing.assert_allclose(fut[..., 1], np.asarray(objective.data.true_fut)[..., 1], atol=1e-9)
    assert moved.data.gt_pred.shape == objective.data.gt_pred.shape
    assert not np.allclose(np.asarray(moved.data.gt_pred), np.asarray(objective.data.gt_pred))
    np.testing.assert_array_equal(np.asarray(moved.data.scenes.speed_mps[:, 0, TARGET_INDEX]), [27, 28, 29])


def test_with_scenes_pads_by_repeating_the_last_scene(objective):
    two = jax.tree.map(lambda a: a[:2], objective.data.scenes)
    moved = with_scenes(objective, two)
    s = np.asarray(moved.data.scenes.s_m)
    assert s.shape[0] == 3
    np.testing.assert_array_equal(s[2], s[1])
    np.testing.assert_allclose(np.asarray(moved.data.true_fut)[2, 0, :, 0], _future_s(objective, [25.0])[0],
                               atol=1e-9)


def test_speed_shifted_scenes_at_no_shift_are_the_base_in_its_dtype():
    jax.config.update("jax_enable_x64", True)  # float64 asked for (the simulation's default is float32)
    shifted, index, names, _ = speed_shifted_scenes(("sc01",), 1, jax.random.key(0), spec=CSLSTM_SPEC,
                                                    sensors=(ToySensor(),), stride_frames=10,
                                                    dtype=jnp.float64)
    again = shifted(0.0)
    assert again.s_m.dtype == jnp.float64 and names == ("sc01",) and list(index) == [0]
    for a, b in zip(jax.tree.leaves(again), jax.tree.leaves(shifted.base)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_recorded_scenes_are_one_clear_scenario_each(tmp_path):
    path = write_highd(tmp_path)
    scenes, index, names, weather = recorded_scenes(f"highd:{path}", spec=CSLSTM_SPEC,
                                                    sensors=(ToySensor(),), dtype=jnp.float64)
    n = scenes.x_m.shape[0]
    assert n >= 1 and list(index) == list(range(n))
    assert names == tuple(f"{path.name}#{i}" for i in range(n))
    np.testing.assert_array_equal(weather.rain_mm_h, np.zeros(n))
    np.testing.assert_array_equal(weather.fog_visibility_m, np.full(n, np.inf))
    # the ego and the target of every cut are kept, and present throughout
    assert np.asarray(scenes.present)[:, :2].all() and scenes.s_m.dtype == jnp.float64


def test_float32_scenes_make_a_float32_objective():
    """With x64 on, float32 scenes keep every float of the objective in float32 (the weights, the
    true future, the Monte-Carlo uniforms, the weather, r and E) and the scenario ids int32."""
    jax.config.update("jax_enable_x64", True)
    scenes, scenario = toy_scenes(2)
    scenes = jax.tree.map(lambda a: a.astype(jnp.float32) if jnp.issubdtype(a.dtype, jnp.floating) else a,
                          scenes)
    E = make_objective(scenes, scenario, prediction_frames(scenes.num_frames)[:1], ToySensor(),
                       ToyPredictor(jnp.asarray(TOY_GAIN, jnp.float32)), names=("range_m",),
                       estimator=EstimatorConfig(kind="mc", samples=2))
    assert E.data.scenario.dtype == jnp.int32
    for name in ("weight", "true_fut", "mc_uniform"):
        assert getattr(E.data, name).dtype == jnp.float32, name
    assert {leaf.dtype for leaf in jax.tree.leaves(E.weather)} == {jnp.dtype(jnp.float32)}
    # r given as Python floats is taken in the objective's dtype: E(r) stays float32
    assert E({"range_m": 40.0}).dtype == jnp.float32


@pytest.mark.parametrize("kind", ["relaxed-reference", "straight-through"])
def test_float32_objective_stays_float32_under_the_reference_draws(kind):
    """The estimators that draw E_ref's own detections (a random detection law) keep float32
    too: the relaxation's temperature and the hard draws are taken in the objective's dtype."""
    jax.config.update("jax_enable_x64", True)
    scenes, scenario = toy_scenes(1)
    scenes = jax.tree.map(lambda a: a.astype(jnp.float32) if jnp.issubdtype(a.dtype, jnp.floating) else a,
                          scenes)
    radar = sensor.Radar(cfg.replace(sensor.load_config("radar"), detection=RadarDetection(law="swerling1")))
    E = make_objective(scenes, scenario, prediction_frames(scenes.num_frames)[:1], radar,
                       ToyPredictor(jnp.asarray(TOY_GAIN, jnp.float32)), names=("hfov_deg",),
                       estimator=EstimatorConfig(kind=kind, reference_draws=2), shard=False)
    # a float64 temperature (a solver's schedule under x64) is taken in float32 as well
    value, grad = jax.jit(jax.value_and_grad(lambda h: E.e2({"hfov_deg": h}, jnp.float64(1.0))))(jnp.float32(10.0))
    assert value.dtype == jnp.float32 and grad.dtype == jnp.float32


def test_float32_suite_objective_stays_float32_under_monte_carlo():
    """A suite's Monte-Carlo draws take the temperature multiplier in the objective's dtype."""
    jax.config.update("jax_enable_x64", True)
    scenes, scenario = toy_scenes(1)
    scenes = jax.tree.map(lambda a: a.astype(jnp.float32) if jnp.issubdtype(a.dtype, jnp.floating) else a,
                          scenes)
    radar = sensor.Radar(cfg.replace(sensor.load_config("radar"), detection=RadarDetection(law="swerling1")))
    E = make_objective(scenes, scenario, prediction_frames(scenes.num_frames)[:1],
                       sensor.Suite((radar, sensor.Camera.from_toml())),
                       ToyPredictor(jnp.asarray(TOY_GAIN, jnp.float32)), names=("radar.hfov_deg",),
                       estimator=EstimatorConfig(kind="mc", samples=2), shard=False)
    value, grad = jax.jit(jax.value_and_grad(lambda h: E.e2({"radar.hfov_deg": h}, jnp.float64(1.0))))(
        jnp.float32(10.0))
    assert value.dtype == jnp.float32 and grad.dtype == jnp.float32
