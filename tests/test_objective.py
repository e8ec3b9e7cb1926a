"""E_RMSE(r) on a stand-in sensor and predictor: values, gradients, estimators, horizons, purity."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.runtime._errors import InputError
from diffsense.metrics import EstimatorConfig
from diffsense.solve import Evaluator
from tests._toy_pipeline import toy_objective

R = "range_m"


@pytest.fixture(scope="module")
def objective():
    return toy_objective(fill="hold")


_e2 = eqx.filter_jit(lambda o, r, t: o.e2({R: r}, t))


def e2(obj, r, tau=1.0):
    """Soft E^2 at r, compiled once per objective: r and tau go in as arrays (a Python float
    under `eqx.filter_jit` would be baked in, one program per point)."""
    return float(_e2(obj, jnp.asarray(r), jnp.asarray(tau)))


_hard = eqx.filter_jit(lambda o, r: o({R: r}, mode="hard"))


def hard(obj, r):
    """Hard E at r, compiled once per objective."""
    return float(_hard(obj, jnp.asarray(r)))


_hard_evaluation = eqx.filter_jit(lambda o, r: o.hard({R: r}))


def test_blind_sensor_is_penalised(objective):
    blind = hard(objective, 0.5)
    seeing = hard(objective, 150.0)
    assert blind > seeing > 0.0
    assert np.isfinite(blind)


def test_gradient_matches_central_differences(objective):
    vg = eqx.filter_jit(lambda o, r: jax.value_and_grad(lambda x: o.e2({R: x}))(r))
    for r in (30.0, 55.0):
        value, grad = vg(objective, jnp.asarray(r))
        h = 1e-4
        fd = (e2(objective, r + h) - e2(objective, r - h)) / (2 * h)
        assert np.isfinite(float(grad))
        np.testing.assert_allclose(float(grad), fd, rtol=1e-5, atol=1e-9)
        np.testing.assert_allclose(float(value), e2(objective, r), rtol=1e-12)


def test_e_is_the_square_root_and_its_gradient_is_a_dict(objective):
    value, grad = eqx.filter_jit(lambda o, r: jax.value_and_grad(o)(r))(objective, {R: 40.0})
    assert set(grad) == {R}
    np.testing.assert_allclose(float(value) ** 2, e2(objective, 40.0), rtol=1e-12)
    g_e2 = eqx.filter_jit(lambda o, x: jax.grad(lambda x: o.e2({R: x}))(x))(objective, 40.0)
    np.testing.assert_allclose(float(grad[R]), float(g_e2) / (2 * float(value)), rtol=1e-12)


def test_jit_and_vmap_of_the_module(objective):
    r = jnp.array([20.0, 40.0, 80.0])
    batch = jax.jit(jax.vmap(objective))({R: r})
    each = [float(jax.jit(objective)({R: x})) for x in r]
    np.testing.assert_allclose(np.asarray(batch), each, rtol=1e-12)
    np.testing.assert_allclose(float(objective({R: 40.0})), each[1], rtol=1e-12)  # op by op
    hard = jax.jit(objective, static_argnames="mode")({R: 40.0}, mode="hard")
    np.testing.assert_allclose(float(hard), float(objective({R: 40.0}, mode="hard")), rtol=1e-12)


def test_unknown_parameter_is_one_line(objective):
    with pytest.raises(InputError, match="unknown toy parameter 'hfov_deg'"):
        objective({"hfov_deg": 3.0})


def test_soft_tends_to_hard_as_temperature_shrinks(objective):
    r = 47.3
    hard_e2 = hard(objective, r) ** 2
    gaps = [abs(e2(objective, r, tau) - hard_e2) for tau in (1.0, 0.1, 1e-3)]
    assert gaps[-1] < 1e-6 * max(hard_e2, 1.0)
    assert gaps[-1] <= gaps[0]


def test_same_seed_same_objective(objective):
    again = toy_objective(fill="hold")
    assert e2(again, 40.0) == e2(objective, 40.0)
    other = toy_objective(fill="hold", key=jax.random.PRNGKey(7))
    assert e2(other, 40.0) != e2(objective, 40.0)  # the noise draws come from the key


def test_evaluator_memoises_counts_and_matches_the_module(objective):
    ev = Evaluator(objective)
    value, grad = ev.value_and_grad(44.0, 2.0)
    assert ev.value_and_grad(44.0, 2.0) == (value, grad) and ev.counts == {"soft": 1, "hard": 0}
    np.testing.assert_allclose(value, e2(objective, 44.0, 2.0), rtol=1e-12)
    e2_soft, e_hard = ev.solver_fns()
    r = jnp.asarray(44.0)
    assert float(jax.jit(e2_soft)(r, 2.0)) == value
    assert float(jax.jit(jax.grad(e2_soft))(r, 2.0)) == grad[0]
    assert e_hard(r) == ev.e_hard(44.0) == pytest.approx(hard(objective, 44.0), rel=1e-12)
    assert ev.counts == {"soft": 1, "hard": 1}


def test_hard_evaluation_carries_its_detections(objective):
    # The record the main job's detections figure reads: the 0/1 detections that produced E_hard,
    # equal to the module's own hard detections, and more of them at a longer range.
    near, far = _hard_evaluation(objective, jnp.asarray(20.0)), _hard_evaluation(objective, jnp.asarray(150.0))
    det = eqx.filter_jit(lambda o: o.detections({R: 20.0}, "hard").p_detect)(objective)
    np.testing.assert_array_equal(np.asarray(near.p_detect), np.asarray(det))
    assert set(np.unique(np.asarray(near.p_detect))) <= {0.0, 1.0}
    assert float(np.sum(far.p_detect)) > float(np.sum(near.p_detect))


def test_horizon_rmse_shapes_and_growth(objective):
    h = _hard_evaluation(objective, jnp.asarray(30.0))
    assert h.rmse_gt.shape == (2, 25) and h.rmse_sensor.shape == (2, 25)
    assert np.all(np.isfinite(h.rmse_gt)) and np.all(np.isfinite(h.rmse_sensor))
    assert h.rmse_sensor[:, -1].mean() > h.rmse_sensor[:, 0].mean()


def test_monte_carlo_estimator_is_deterministic_and_differentiable():
    mc = toy_objective(n=2, instants=4, fill="interp", key=jax.random.PRNGKey(1),
                       estimator=EstimatorConfig(kind="mc", samples=3, relax_temperature=0.3))
    v1, g1 = Evaluator(mc).value_and_grad(40.0)
    v2, g2 = eqx.filter_jit(jax.value_and_grad(lambda r, m: m.e2({R: r})))(40.0, mc)
    np.testing.assert_allclose([v1, g1[0]], [float(v2), float(g2)], rtol=1e-12)
    assert np.isfinite(g1[0])
    h = 1e-4
    fd = (e2(mc, 40.0 + h) - e2(mc, 40.0 - h)) / (2 * h)
    np.testing.assert_allclose(g1[0], fd, rtol=1e-5, atol=1e-9)


def test_monte_carlo_memory_does_not_grow_with_samples():
    # Each sample is rematerialised in the backward pass: without it the compiled value-and-gradient
    # keeps every sample's activations (here 10x the K = 2 scratch memory at K = 32; on the default
    # problem K = 64 did not fit in 24 GB).
    scratch = {}
    for k in (2, 32):
        mc = toy_objective(n=2, instants=4, fill="interp",
                           estimator=EstimatorConfig(kind="mc", samples=k, relax_temperature=0.3))
        vg = jax.jit(jax.value_and_grad(lambda r, m: m.e2({R: r})))
        compiled = vg.lower(40.0, mc).compile()
        scratch[k] = compiled.memory_analysis().temp_size_in_bytes
    assert scratch[32] < 2 * scratch[2], scratch


@pytest.mark.parametrize("kind", ["mean-field", "mc"])
def test_sq_error_by_variant_and_step_adds_up_to_the_objective(kind):
    obj = toy_objective(n=2, instants=4, fill="interp",
                        estimator=EstimatorConfig(kind=kind, samples=3, relax_temperature=0.3))
    data, r, tau = obj.data, 40.0, 1.0
    sq = eqx.filter_jit(lambda o: o.sq_error({R: r}, tau))(obj)
    assert sq.shape == (2, 25) and np.all(np.isfinite(sq)) and np.all(sq >= 0.0)

    def weighted(r_, w, o):
        return jnp.sum(w * o.sq_error({R: r_}, tau)) / (jnp.sum(o.data.weight) * 25)

    w = jnp.broadcast_to(data.weight[:, None], sq.shape)
    value, grad = Evaluator(obj).value_and_grad(r, tau)
    np.testing.assert_allclose(float(eqx.filter_jit(weighted)(r, w, obj)), value, rtol=1e-12)
    # d/dw of dE^2/dr: each (variant, step)'s share of the gradient; the shares add up to it.
    shares = eqx.filter_jit(jax.grad(jax.grad(weighted, argnums=0), argnums=1))(r, w, obj)
    np.testing.assert_allclose(float(jnp.sum(shares * w)), grad[0], rtol=1e-10, atol=1e-14)


def test_estimator_config_rejects_bad_values():
    with pytest.raises(InputError, match="unknown estimator"):
        EstimatorConfig(kind="exact")
    with pytest.raises(InputError, match="samples"):
        EstimatorConfig(kind="mc", samples=0)
