"""Forward mode through the CS-LSTM: the recurrences' tangent rule against autodiff of the textbook
LSTM, and `diffsense.metrics.value_and_grad` (what the solver runs for one parameter) against
reverse mode and central differences, in float64."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _textbook_lstm import textbook_lstm

import diffsense as ds
from diffsense.metrics import value_and_grad
from diffsense.predictors import _lstm_forward, forward_mode
from diffsense.predictors._lstm import lstm_last, lstm_repeat
from diffsense.solve._evaluator import _value_and_grad as evaluator_value_and_grad


def _cases(rng):
    t, n, n_in, hidden = 5, 3, 6, 4
    w = [rng.normal(size=s) for s in ((n_in, 4 * hidden), (hidden, 4 * hidden), (4 * hidden,))]
    emb = [rng.normal(size=(2, n_in)), rng.normal(size=n_in)]

    def embedded(x, a, c):
        z = x @ a + c
        return jnp.where(z >= 0, z, 0.1 * z)

    # Embedding pre-activations exactly at leaky_relu's kink (a zero history row, a zero bias):
    # the primal takes the slope-1 branch there, and so must the tangent.
    xy = rng.normal(size=(t, n, 2))
    xy[:, 0] = 0.0
    emb[1][:2] = 0.0
    return [
        (lambda x, *p: lstm_last(x, *p), lambda x, *p: textbook_lstm(x, *p)[-1], rng.normal(size=(t, n, n_in)), w),
        (lambda x, *p: lstm_last(x, *p[:3], emb=tuple(p[3:])),
         lambda x, *p: textbook_lstm(embedded(x, *p[3:]), *p[:3])[-1], xy, w + emb),
        (lambda x, *p: lstm_repeat(t, x, *p),
         lambda x, *p: textbook_lstm(jnp.broadcast_to(x, (t,) + x.shape), *p), rng.normal(size=(n, n_in)), w),
    ]


@pytest.mark.parametrize("stack_rows", [512, 0], ids=["rows-stacked", "rows-apart"])
def test_recurrence_tangents_match_autodiff(monkeypatch, stack_rows):
    monkeypatch.setattr(_lstm_forward, "STACK_ROWS", stack_rows)
    rng = np.random.default_rng(7)
    for got_fn, want_fn, x, p in _cases(rng):
        args = (x, *p)
        tangents = tuple(rng.normal(size=np.shape(a)) for a in args)
        want, d_want = jax.jvp(want_fn, args, tangents)
        with forward_mode():
            got, d_got = jax.jvp(got_fn, args, tangents)  # every argument's tangent, weights too
            got_x, d_got_x = jax.jit(lambda x, dx: jax.jvp(lambda x: got_fn(x, *p), (x,), (dx,)))(x, tangents[0])
        _, d_want_x = jax.jvp(lambda x: want_fn(x, *p), (x,), (tangents[0],))
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-14)
        np.testing.assert_allclose(d_got, d_want, rtol=1e-12, atol=1e-13)
        np.testing.assert_allclose(got_x, want, rtol=1e-13, atol=1e-14)
        np.testing.assert_allclose(d_got_x, d_want_x, rtol=1e-12, atol=1e-13)


def test_a_tangent_on_one_argument_alone_matches_autodiff():
    # The others' tangents are symbolic zeros (`symbolic_zeros=True`): the rule forms only what
    # is given, and a weight's tangent alone (the input held fixed) still reaches the output.
    rng = np.random.default_rng(9)
    for case, (got_fn, want_fn, x, p) in enumerate(_cases(rng)):
        args = (x, *p)
        for i, arg in enumerate(args):
            dt = rng.normal(size=np.shape(arg))

            def only(fn, i=i):
                return lambda a: fn(*args[:i], a, *args[i + 1:])

            _, d_want = jax.jvp(only(want_fn), (arg,), (dt,))
            with forward_mode():
                _, d_got = jax.jvp(only(got_fn), (arg,), (dt,))
            np.testing.assert_allclose(d_got, d_want, rtol=1e-12, atol=1e-13, err_msg=f"case {case}, argument {i}")


def test_primal_and_tangent_rows_share_one_product_below_stack_rows():
    # The documented policy: fewer than STACK_ROWS rows take one [2N, k] product, STACK_ROWS
    # rows or more take two; decided by the rows, however many columns they have.
    rows = _lstm_forward.STACK_ROWS
    w = jnp.ones((rows + 3, 8))
    for n, products in ((rows - 1, 1), (rows, 2)):
        a = jnp.ones((n, rows + 3))
        jaxpr = jax.make_jaxpr(_lstm_forward._stacked)(a, 2.0 * a, w)
        assert sum(e.primitive.name == "dot_general" for e in jaxpr.jaxpr.eqns) == products, n
        got, d_got = _lstm_forward._stacked(a, 2.0 * a, w)
        np.testing.assert_array_equal(got, a @ w)
        np.testing.assert_array_equal(d_got, (2.0 * a) @ w)


def test_forward_mode_is_a_switch_read_while_tracing():
    rng = np.random.default_rng(8)
    got_fn, _, x, p = _cases(rng)[0]
    with pytest.raises(TypeError, match="custom_vjp"):  # reverse mode's rule outside the block
        jax.jvp(lambda x: got_fn(x, *p), (x,), (x,))
    assert not _lstm_forward.forward_mode_active()
    with forward_mode():
        assert _lstm_forward.forward_mode_active()
    assert not _lstm_forward.forward_mode_active()


def _radar(params):
    problem = ds.Problem(sensor="radar", params=params, scenarios=["sc01"], variants=2, seed=0,
                         predictor=ds.predictors.init_predictor(False, 0), prediction_stride_frames=20,
                         predictor_dtype="float64")  # float64 throughout for central differences
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


def test_the_solver_program_has_no_backward_pass_for_one_parameter(radar):
    # A reverse pass shows as a reverse scan (the LSTMs' backward); forward mode has none.
    jaxpr = eqx.filter_make_jaxpr(lambda E, x: evaluator_value_and_grad(E, x, jnp.asarray(2.0)))
    one = _radar({"hfov_deg": (30.0, 180.0)})
    assert "reverse=True" not in str(jaxpr(one, jnp.full(1, 50.0))[0])
    assert "reverse=True" in str(jaxpr(radar, jnp.asarray([50.0, 80.0]))[0])


@pytest.mark.parametrize("name, extremes", [("hfov_deg", (0.01, 360.0)), ("range_m", (0.1, 1000.0))])
def test_forward_mode_is_finite_at_the_parameters_extremes(radar, name, extremes):
    for x in extremes:
        (value, grad), _ = _both(radar, name, jnp.asarray(x), 1.0)
        assert np.isfinite(float(value)) and np.isfinite(float(grad))
