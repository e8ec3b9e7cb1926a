"""What `ds.objective(problem)` builds from a Problem: the problem's scenes from its seed's first
key, the detection draws from its second, its estimator and precision, its predictor in the
precision asked for, and the problem's own sensor, built once (on the toy sensor and predictor)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffsense as ds
from diffsense.metrics import EstimatorConfig, make_objective, speed_shifted_scenes
from diffsense.predictors import CastPredictor
from diffsense.sensors import relevance_stand_ins
from diffsense.study import memory_estimate_bytes
from diffsense.tracks import prediction_frames
from tests._toy_pipeline import TOY_GAIN, ToyPredictor, ToySensor

ROOT = Path(__file__).resolve().parents[1]
BUILT = []


def _counted_toy():
    BUILT.append(1)
    return ToySensor()


ds.sensors.register("counted_toy", _counted_toy)


@pytest.fixture(scope="module")
def built():
    BUILT.clear()
    toy = ToyPredictor(jnp.asarray(TOY_GAIN))
    estimator = EstimatorConfig(kind="mc", samples=2)
    problem = ds.Problem(sensor="counted_toy", params={"range": (10, 100)}, scenarios=["sc01"], variants=2, seed=3,
                         prediction_stride_frames=40, predictor=toy, estimator=estimator)
    E = ds.objective(problem)
    return problem, E, toy, estimator


def test_building_a_problem_and_its_objective_builds_the_sensor_once(built):
    problem, E, _, _ = built
    assert problem.sensor_kind == "toy" and problem.params == {"range_m": (10.0, 100.0)}
    problem.replace(variants=1, seed=4, estimator="hard", steps=[10, 100])  # no sensing keyword among them
    assert len(BUILT) == 1


def test_the_objective_is_its_seeds_scenes_and_draws_and_its_estimator_in_float64(built):
    problem, E, toy, estimator = built
    assert E.dtype == jnp.float64 and E.scenario_names == ("sc01",) and E.estimator == estimator
    assert E.predictor is toy  # "auto": any predictor but the CS-LSTM computes in E's own precision
    scenes_key, draws_key = jax.random.split(jax.random.PRNGKey(3))
    sensor = ToySensor()
    expected = speed_shifted_scenes(("sc01",), 2, scenes_key, spec=toy.spec,  # variant 1 is randomised
                                    sensors=[sensor, *relevance_stand_ins(problem.params)],
                                    stride_frames=40, dtype=jnp.float64)[0].base
    np.testing.assert_array_equal(np.asarray(E.data.scenes.x_m), np.asarray(expected.x_m))
    frames = prediction_frames(expected.num_frames, 40, toy.spec, expected.dt_s)
    by_hand = make_objective(expected, np.zeros(2, np.int32), frames, sensor, toy,
                             names=tuple(problem.params), estimator=estimator, key=draws_key)
    np.testing.assert_array_equal(jax.random.key_data(E.data.noise_key), jax.random.key_data(by_hand.data.noise_key))
    np.testing.assert_array_equal(np.asarray(E.data.mc_uniform), np.asarray(by_hand.data.mc_uniform))


def test_the_predictor_computes_in_the_precision_asked_for(built):
    problem, E, toy, _ = built
    cast = ds.objective(problem.replace(predictor_dtype="float32", estimator="auto")).predictor
    assert isinstance(cast, CastPredictor) and cast.inner is toy and cast.dtype == "float32"
    single = ds.objective(problem.replace(float64=False, predictor_dtype="float32", estimator="auto"))
    assert single.dtype == jnp.float32 and single.predictor is toy  # a float32 E: nothing to cast


def test_float64_switches_jax_to_64_bits_in_a_fresh_process():
    code = ("import jax, jax.numpy as jnp, diffsense as ds; from tests._toy_pipeline import ToyPredictor, ToySensor; "
            "before = jax.config.jax_enable_x64; "
            "E = ds.objective(ds.Problem(sensor=ToySensor(), params={'range_m': (10.0, 100.0)}, scenarios=['sc01'], "
            "variants=1, prediction_stride_frames=100, predictor=ToyPredictor(jnp.float32(0.01)))); "
            "print(before, E.dtype, jax.config.jax_enable_x64)")
    env = {k: v for k, v in os.environ.items() if k != "JAX_ENABLE_X64"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["False", "float64", "True"]


def test_the_memory_estimate_is_variants_frames_vehicles_and_fields(tmp_path):
    # sc01 runs 20 s at 10 Hz (201 frames) with 5 vehicles and no background ones
    assert memory_estimate_bytes(ds.Problem(scenarios=["sc01"], variants=2)) == 2 * 201 * 5 * 8 * 20
    problem = ds.Problem(scenarios=["sc01", "sc02"], variants=3, float64=False, background_vehicles=10,
                         estimator=EstimatorConfig(kind="mc", samples=6))
    assert memory_estimate_bytes(problem) == 2 * 3 * 201 * 15 * 4 * (6 + 20)
    assert memory_estimate_bytes(ds.Problem(scenarios=["sc01"], estimator="mean-field", float64=False)) == \
        8 * 201 * 5 * 4 * 20  # the Monte-Carlo draws only for "mc"
    csv = tmp_path / "t.csv"
    csv.write_text("")
    assert memory_estimate_bytes(ds.Problem(scenes=f"ngsim:{csv}")) == 0
