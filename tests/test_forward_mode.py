"""Forward mode through the whole objective: `diffsense.metrics.value_and_grad` (what the solver
runs for one parameter) against reverse mode and central differences in float64, its program
without a backward pass, and finite at the parameters' extremes. The recurrences' own tangent
rule: tests/test_lstm_recurrences.py."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffsense as ds
from diffsense.metrics import value_and_grad


def _radar(params):
    problem = ds.Problem(sensor="radar", params=params, scenarios=["sc01"], variants=2, seed=0,
                         predictor=ds.predictors.init_predictor(False, 0), prediction_stride_frames=20,
                         predictor_dtype="float64",  # float64 throughout for central differences
                         # the physical law's relaxed-reference E over 4 draws: smooth, and cheap
                         estimator=ds.metrics.EstimatorConfig(reference_draws=4))
    return ds.objective(problem)


@pytest.fixture(scope="module")
def radar():
    return _radar({"hfov_deg": (30.0, 180.0), "range_m": (30.0, 200.0)})


@eqx.filter_jit
def _both(E, name, x, tau):
    fixed = {"hfov_deg": 50.0, "range_m": 80.0}

    def e2(v):
        return E.e2(fixed | {name: v}, tau)

    return value_and_grad(e2)(x), jax.value_and_grad(e2)(x)


@eqx.filter_jit
def _e2(E, r, tau):
    return E.e2(r, tau)


@pytest.mark.parametrize("name, x", [("hfov_deg", 50.0), ("range_m", 80.0)])
def test_one_parameter_gradient_equals_reverse_mode_and_central_differences(radar, name, x):
    (value, grad), (value_rev, grad_rev) = _both(radar, name, jnp.asarray(x), 2.0)
    np.testing.assert_allclose(float(value), float(value_rev), rtol=1e-13)
    np.testing.assert_allclose(float(grad), float(grad_rev), rtol=1e-10, atol=1e-12)
    fixed, h = {"hfov_deg": 50.0, "range_m": 80.0}, 1e-3
    up, down = (float(_e2(radar, fixed | {name: x + s}, 2.0)) for s in (h, -h))
    np.testing.assert_allclose(float(grad), (up - down) / (2 * h), rtol=1e-5, atol=1e-10)


def test_several_parameters_take_reverse_mode_and_the_gradient_keeps_r_structure(radar):
    r = {"hfov_deg": jnp.asarray(50.0), "range_m": jnp.asarray(80.0)}
    got = eqx.filter_jit(lambda E, r: value_and_grad(lambda q: E.e2(q, 2.0))(r))(radar, r)
    want = eqx.filter_jit(lambda E, r: jax.value_and_grad(lambda q: E.e2(q, 2.0))(r))(radar, r)
    assert set(got[1]) == set(r)
    assert float(got[0]) == float(want[0])
    assert all(float(got[1][k]) == float(want[1][k]) for k in r)


def test_one_number_gives_a_gradient_shaped_like_r():
    value, grad = value_and_grad(lambda q: q["a"][0] ** 3)({"a": jnp.asarray([2.0])})
    assert float(value) == 8.0 and set(grad) == {"a"}
    assert grad["a"].shape == (1,) and grad["a"].dtype == jnp.float64 and float(grad["a"][0]) == 12.0


def test_a_non_scalar_function_is_refused():
    with pytest.raises(TypeError, match="scalar"):
        value_and_grad(lambda r: jnp.stack([r, r]))(jnp.asarray(1.0))


def test_one_parameter_takes_forward_mode_and_several_reverse(radar):
    # A reverse pass shows as a reverse scan (the LSTMs' backward); forward mode has none.
    one = _radar({"hfov_deg": (30.0, 180.0)})
    jaxpr = eqx.filter_make_jaxpr(lambda E, r: value_and_grad(lambda q: E.e2(q, 2.0))(r))
    assert "reverse=True" not in str(jaxpr(one, {"hfov_deg": jnp.asarray(50.0)})[0])
    assert "reverse=True" in str(jaxpr(radar, {"hfov_deg": jnp.asarray(50.0), "range_m": jnp.asarray(80.0)})[0])


@pytest.mark.parametrize("name, extremes", [("hfov_deg", (0.01, 360.0)), ("range_m", (0.1, 1000.0))])
def test_forward_mode_is_finite_at_the_parameters_extremes(radar, name, extremes):
    for x in extremes:
        (value, grad), _ = _both(radar, name, jnp.asarray(x), 1.0)
        assert np.isfinite(float(value)) and np.isfinite(float(grad))
