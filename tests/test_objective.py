"""E_RMSE(r) on a stand-in sensor and predictor: values, gradients, estimators, horizons."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.metrics import EstimatorConfig, make_objective
from diffsense.tracks import prediction_frames
from tests._toy_pipeline import TOY_GAIN, toy_detect, toy_predict, toy_scenes


@pytest.fixture(scope="module")
def objective():
    scenes, scenario = toy_scenes()
    frames = prediction_frames(scenes.num_frames)
    return make_objective(scenes, scenario, frames, toy_detect(), toy_predict, TOY_GAIN, fill="hold")


def test_blind_sensor_is_penalised(objective):
    blind = objective.e_hard(0.5)
    seeing = objective.e_hard(150.0)
    assert blind > seeing > 0.0
    assert np.isfinite(blind)


def test_gradient_matches_central_differences(objective):
    for r in (30.0, 55.0):
        value, grad = objective.value_and_grad(r, 1.0)
        h = 1e-4
        fd = (objective.e2_soft(r + h) - objective.e2_soft(r - h)) / (2 * h)
        assert np.isfinite(float(grad))
        np.testing.assert_allclose(float(grad), float(fd), rtol=1e-5, atol=1e-9)
        np.testing.assert_allclose(float(value), float(objective.e2_soft(r)), rtol=1e-12)


def test_soft_tends_to_hard_as_temperature_shrinks(objective):
    r = 47.3
    hard = objective.e_hard(r) ** 2
    gaps = [abs(float(objective.e2_soft(r, tau)) - hard) for tau in (1.0, 0.1, 1e-3)]
    assert gaps[-1] < 1e-6 * max(hard, 1.0)
    assert gaps[-1] <= gaps[0]


def test_same_seed_same_objective(objective):
    scenes, scenario = toy_scenes()
    again = make_objective(scenes, scenario, objective.frames, toy_detect(), toy_predict, TOY_GAIN, fill="hold")
    assert again.value_and_grad(40.0) == objective.value_and_grad(40.0)
    other = make_objective(scenes, scenario, objective.frames, toy_detect(), toy_predict, TOY_GAIN, fill="hold",
                           key=jax.random.PRNGKey(7))
    assert other.e2_soft(40.0) != objective.e2_soft(40.0)  # the noise draws come from the key


def test_solver_functions_call_the_compiled_program(objective):
    e2_soft, e_hard = objective.solver_fns()
    r = jnp.asarray(44.0)
    value, grad = objective.value_and_grad(44.0, 2.0)
    assert float(jax.jit(e2_soft)(r, 2.0)) == value
    assert float(jax.jit(jax.grad(e2_soft))(r, 2.0)) == grad
    assert e_hard(r) == objective.e_hard(44.0)


def test_horizon_rmse_shapes_and_growth(objective):
    gt, sensor = objective.horizon_rmse(30.0)
    assert gt.shape == (2, 25) and sensor.shape == (2, 25)
    assert np.all(np.isfinite(gt)) and np.all(np.isfinite(sensor))
    assert sensor[:, -1].mean() > sensor[:, 0].mean()


def test_monte_carlo_estimator_is_deterministic_and_differentiable():
    scenes, scenario = toy_scenes(n=2)
    frames = prediction_frames(scenes.num_frames)[:4]
    mc = make_objective(scenes, scenario, frames, toy_detect(), toy_predict, TOY_GAIN, fill="interp",
                        estimator=EstimatorConfig(kind="mc", samples=3, relax_temperature=0.3),
                        key=jax.random.PRNGKey(1))
    v1, g1 = mc.value_and_grad(40.0)
    v2, g2 = jax.jit(jax.value_and_grad(mc.traced_e2))(40.0, 1.0)
    np.testing.assert_allclose([v1, g1], [float(v2), float(g2)], rtol=1e-12)
    assert np.isfinite(float(g1))
    h = 1e-4
    fd = (mc.e2_soft(40.0 + h) - mc.e2_soft(40.0 - h)) / (2 * h)
    np.testing.assert_allclose(float(g1), float(fd), rtol=1e-5, atol=1e-9)


def test_monte_carlo_memory_does_not_grow_with_samples():
    # Each sample is rematerialised in the backward pass: without it the compiled value-and-gradient
    # keeps every sample's activations (here 10x the K = 2 scratch memory at K = 32; on the default
    # problem K = 64 did not fit in 24 GB).
    scenes, scenario = toy_scenes(n=2)
    frames = prediction_frames(scenes.num_frames)[:4]
    scratch = {}
    for k in (2, 32):
        mc = make_objective(scenes, scenario, frames, toy_detect(), toy_predict, TOY_GAIN, fill="interp",
                            estimator=EstimatorConfig(kind="mc", samples=k, relax_temperature=0.3))
        compiled = jax.jit(jax.value_and_grad(mc.traced_e2)).lower(40.0, 1.0, mc.data).compile()
        scratch[k] = compiled.memory_analysis().temp_size_in_bytes
    assert scratch[32] < 2 * scratch[2], scratch


@pytest.mark.parametrize("kind", ["mean-field", "mc"])
def test_sq_error_by_variant_and_step_adds_up_to_the_objective(kind):
    scenes, scenario = toy_scenes(n=2)
    frames = prediction_frames(scenes.num_frames)[:4]
    obj = make_objective(scenes, scenario, frames, toy_detect(), toy_predict, TOY_GAIN, fill="interp",
                         estimator=EstimatorConfig(kind=kind, samples=3, relax_temperature=0.3))
    data, r, tau = obj.data, 40.0, 1.0
    sq = jax.jit(obj.traced_sq_error)(r, tau, data)
    assert sq.shape == (scenario.shape[0], 25) and np.all(np.isfinite(sq)) and np.all(sq >= 0.0)

    def weighted(r_, w):
        return jnp.sum(w * obj.traced_sq_error(r_, tau, data)) / (jnp.sum(data.weight) * 25)

    w = jnp.broadcast_to(data.weight[:, None], sq.shape)
    value, grad = obj.value_and_grad(r, tau)
    np.testing.assert_allclose(float(jax.jit(weighted)(r, w)), value, rtol=1e-12)
    # d/dw of dE^2/dr: each (variant, step)'s share of the gradient; the shares add up to it.
    shares = jax.jit(jax.grad(jax.grad(weighted, argnums=0), argnums=1))(r, w)
    np.testing.assert_allclose(float(jnp.sum(shares * w)), grad, rtol=1e-10, atol=1e-14)


def test_estimator_config_rejects_bad_values():
    from diffsense.errors import InputError

    with pytest.raises(InputError, match="unknown estimator"):
        EstimatorConfig(kind="exact")
    with pytest.raises(InputError, match="samples"):
        EstimatorConfig(kind="mc", samples=0)
