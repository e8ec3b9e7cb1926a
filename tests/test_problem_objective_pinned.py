"""What `ds.objective(problem)` builds from a Problem, pinned: the problem's scenes from its
seed's first key, the detection draws from its second, its estimator, in float64 (on the toy
predictor)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

import diffsense as ds
from diffsense.metrics import EstimatorConfig, make_objective, speed_shifted_scenes
from diffsense.sensors._mount import relevance_stand_ins
from diffsense.tracks import prediction_frames
from tests._toy_pipeline import TOY_GAIN, ToyPredictor


def test_the_objective_of_a_problem_is_its_seeds_scenes_and_draws_and_its_estimator_in_float64():
    toy = ToyPredictor(jnp.asarray(TOY_GAIN))
    estimator = EstimatorConfig(kind="mc", samples=2)
    problem = ds.Problem(scenarios=["sc01"], variants=2, seed=3, prediction_stride_frames=40, predictor=toy,
                         estimator=estimator)
    E = ds.objective(problem)
    assert E.dtype == jnp.float64 and E.scenario_names == ("sc01",) and E.estimator == estimator
    scenes_key, draws_key = jax.random.split(jax.random.PRNGKey(3))
    expected = speed_shifted_scenes(("sc01",), 2, scenes_key, spec=toy.spec,  # variant 1 is randomised
                                    sensors=[problem.make_sensor(), *relevance_stand_ins(problem.params)],
                                    stride_frames=40, dtype=jnp.float64)[0].base
    np.testing.assert_array_equal(np.asarray(E.data.scenes.x_m), np.asarray(expected.x_m))
    frames = prediction_frames(expected.num_frames, 40, toy.spec, expected.dt_s)
    by_hand = make_objective(expected, np.zeros(2, np.int32), frames, problem.make_sensor(), toy,
                             names=tuple(problem.params), estimator=estimator, key=draws_key)
    np.testing.assert_array_equal(jax.random.key_data(E.data.noise_key), jax.random.key_data(by_hand.data.noise_key))
    np.testing.assert_array_equal(np.asarray(E.data.mc_uniform), np.asarray(by_hand.data.mc_uniform))
