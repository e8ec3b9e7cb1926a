"""The assembled pipeline (real scenes, sensors and CS-LSTM): gradients and the solve's guarantee.

A randomly initialised CS-LSTM stands in for trained weights: these tests check the plumbing and
the mathematics, which do not depend on what the network learnt.
"""

from __future__ import annotations

import jax
import numpy as np
import pytest
from flax import nnx

import diffsense as ds
from diffsense.predictors import CSLSTM, CSLSTMPredictor
from diffsense.solve import Evaluator, SolveConfig, solve


@pytest.fixture(scope="module")
def predictor() -> CSLSTMPredictor:
    return CSLSTMPredictor.from_model(CSLSTM(rngs=nnx.Rngs(0)))


def _problem(predictor, sensor, param, scenarios=("sc05",)):
    problem = ds.Problem(sensor=sensor, params={param: (1.0, 300.0)}, scenarios=scenarios, variants=2,
                         prediction_stride_frames=20, float64=True, predictor_dtype="float64", predictor=predictor)
    return Evaluator(ds.objective(problem))


@pytest.mark.slow
@pytest.mark.parametrize("sensor, param, r", [("radar", "hfov", 40.0), ("camera", "range", 60.0)])
def test_gradient_matches_central_differences(predictor, sensor, param, r):
    obj = _problem(predictor, sensor, param)
    value, (grad,) = obj.value_and_grad(r, 2.0)
    h = 1e-3
    fd = (obj.e2_soft(r + h, 2.0) - obj.e2_soft(r - h, 2.0)) / (2 * h)
    assert np.isfinite(value) and np.isfinite(grad)
    np.testing.assert_allclose(grad, fd, rtol=1e-5, atol=1e-10)
    # The module itself is the same objective (jit of grad, float64).
    E = obj.objective
    name = next(iter(E.names))
    traced = jax.jit(jax.grad(lambda x, E: E.e2({name: x}, 2.0)))(r, E)
    np.testing.assert_allclose(float(traced), grad, rtol=1e-10)


@pytest.mark.slow
@pytest.mark.parametrize(
    "sensor, param, interval",
    [("radar", "hfov", (30.0, 180.0)), ("radar", "range", (30.0, 200.0)),
     ("camera", "hfov", (30.0, 180.0)), ("camera", "range", (30.0, 200.0))],
)
def test_continuous_answer_is_at_least_as_good_as_the_best_step(predictor, sensor, param, interval):
    obj = _problem(predictor, sensor, param)
    e2_soft, e_hard = obj.solver_fns()
    result = solve(e2_soft, e_hard, interval, config=SolveConfig())
    assert result.E_hard_star <= min(p.E_hard for p in result.sweep)
    assert interval[0] <= result.r_star <= interval[1]
    assert result.evaluations["objective"] + result.evaluations["gradient"] <= 20
    assert obj.e_hard(result.r_star) == result.E_hard_star
