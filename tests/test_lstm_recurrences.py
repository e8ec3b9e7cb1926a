"""The CS-LSTM's recurrences and their hand-written derivative rules, against JAX's autodiff of the
textbook LSTM in float64: values, reverse-mode gradients with the gates kept and recomputed,
forward-mode tangents with primal and tangent rows stacked and apart, one argument's tangent
alone, float32 kept in every mode, and leaky_relu's branch at its kink.

The recurrences are private (`diffsense.predictors._lstm`): they are the numerics under test,
and the public entry points reach only one of the two backward and tangent paths a test can size.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _textbook_lstm import textbook_lstm

from diffsense.predictors import _lstm, _lstm_forward, forward_mode
from diffsense.predictors._lstm import leaky_relu, lstm_last, lstm_repeat

T = 5


def _embedded(x, a, c):  # leaky_relu(x @ a + c), slope 0.1
    z = x @ a + c
    return jnp.where(z >= 0, z, 0.1 * z)


def _cases(rng):
    """(recurrence, its textbook form, input, weights) for the encoder (plain and embedded) and
    the decoder."""
    n, n_in, hidden = 3, 6, 4
    w = [rng.normal(size=s) for s in ((n_in, 4 * hidden), (hidden, 4 * hidden), (4 * hidden,))]
    emb = [rng.normal(size=(2, n_in)), rng.normal(size=n_in)]
    # Embedding pre-activations exactly at leaky_relu's kink (a zero history row, a zero bias):
    # the primal takes the slope-1 branch there, and so must the gradient and the tangent.
    xy = rng.normal(size=(T, n, 2))
    xy[:, 0] = 0.0
    emb[1][:2] = 0.0
    return [
        (lambda x, *p: lstm_last(x, *p), lambda x, *p: textbook_lstm(x, *p)[-1], rng.normal(size=(T, n, n_in)), w),
        (lambda x, *p: lstm_last(x, *p[:3], emb=tuple(p[3:])),
         lambda x, *p: textbook_lstm(_embedded(x, *p[3:]), *p[:3])[-1], xy, w + emb),
        (lambda x, *p: lstm_repeat(T, x, *p),
         lambda x, *p: textbook_lstm(jnp.broadcast_to(x, (T,) + x.shape), *p), rng.normal(size=(n, n_in)), w),
    ]


@pytest.mark.parametrize("remat_bytes", [16 * 2**20, 0], ids=["gates-kept", "gates-recomputed"])
def test_values_and_gradients_match_autodiff(monkeypatch, remat_bytes):
    # Value and gradient w.r.t. every argument (weights too: training uses them). Both ways of the
    # backward pass: the forward pass's gates kept, and recomputed (what reverse mode runs for
    # batches above REMAT_BYTES, which no small test reaches unless the threshold is lowered).
    monkeypatch.setattr(_lstm, "REMAT_BYTES", remat_bytes)
    rng = np.random.default_rng(13)
    for got_fn, want_fn, x, p in _cases(rng):
        probe = rng.normal(size=np.shape(want_fn(x, *p)))
        np.testing.assert_allclose(got_fn(x, *p), want_fn(x, *p), rtol=1e-13, atol=1e-14)
        argnums = tuple(range(len(p) + 1))
        got = jax.grad(lambda *a: jnp.sum(probe * got_fn(*a)), argnums=argnums)(x, *p)
        want = jax.grad(lambda *a: jnp.sum(probe * want_fn(*a)), argnums=argnums)(x, *p)
        for g, ref in zip(got, want, strict=True):
            np.testing.assert_allclose(g, ref, rtol=1e-12, atol=1e-13)
        # Under jit as well (XLA fuses the unrolled forward differently from eager mode).
        np.testing.assert_allclose(jax.jit(got_fn)(x, *p), want_fn(x, *p), rtol=1e-13, atol=1e-14)


@pytest.mark.parametrize("stack_rows", [512, 0], ids=["rows-stacked", "rows-apart"])
def test_tangents_match_autodiff(monkeypatch, stack_rows):
    # Both ways of the tangent products: primal and tangent rows in one product (below
    # STACK_ROWS rows) and in two.
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
    # The others' tangents are symbolic zeros: the rule forms only what is given, and a weight's
    # tangent alone (the input held fixed) still reaches the output.
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


def test_forward_mode_is_a_switch_read_while_tracing():
    got_fn, _, x, p = _cases(np.random.default_rng(8))[0]
    for _ in range(2):  # reverse mode's rule outside the block, before it and after it
        with pytest.raises(TypeError, match="custom_vjp"):
            jax.jvp(lambda x: got_fn(x, *p), (x,), (x,))
        with forward_mode():
            jax.jvp(lambda x: got_fn(x, *p), (x,), (x,))


@pytest.mark.parametrize("remat_bytes", [16 * 2**20, 0], ids=["gates-kept", "gates-recomputed"])
def test_float32_recurrences_stay_float32_in_every_mode(monkeypatch, remat_bytes):
    # The predictor runs in float32 inside a float64 solver (x64 on): values, reverse-mode
    # gradients and forward-mode tangents keep float32 throughout (a float64 state or zero would
    # promote the whole pass, at twice the cost).
    monkeypatch.setattr(_lstm, "REMAT_BYTES", remat_bytes)
    rng = np.random.default_rng(3)
    n, n_in, hidden = 3, 5, 4
    f32 = lambda *shape: jnp.asarray(rng.normal(size=shape), jnp.float32)
    w = (f32(n_in, 4 * hidden), f32(hidden, 4 * hidden), f32(4 * hidden))
    emb = (f32(2, n_in), f32(n_in))
    cases = [(lambda x: lstm_last(x, *w), f32(4, n, n_in)), (lambda x: lstm_last(x, *w, emb=emb), f32(4, n, 2)),
             (lambda x: lstm_repeat(4, x, *w), f32(n, n_in))]
    for fn, x in cases:
        value, pullback = jax.vjp(fn, x)
        (grad,) = pullback(jnp.ones_like(value))
        with forward_mode():
            primal, tangent = jax.jvp(fn, (x,), (jnp.ones_like(x),))
        dtypes = {a.dtype for a in (value, grad, primal, tangent)}
        assert dtypes == {jnp.dtype(jnp.float32)}, dtypes


def test_leaky_relu_takes_the_slope_one_branch_at_zero():
    # One convention at the kink for every way the network is differentiated.
    x = jnp.array([-2.0, 0.0, 3.0])
    np.testing.assert_array_equal(leaky_relu(x), [-0.2, 0.0, 3.0])
    np.testing.assert_array_equal(jax.vmap(jax.grad(leaky_relu))(x), [0.1, 1.0, 1.0])
