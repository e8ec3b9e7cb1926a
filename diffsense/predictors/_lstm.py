"""The LSTM recurrences of CS-LSTM with hand-written backward passes.

`lstm_last(x, w_ih, w_hh, b)`: the encoder, a time-major sequence [T, N, in] -> the last hidden
state [N, H]. `lstm_repeat(steps, x, w_ih, w_hh, b)`: the decoder, whose input [N, in] is the same
at every step -> all hidden states [T, N, H]; its input is projected once and the gradient of the
projection is the sum of the per-step gate gradients. `b` is b_ih + b_hh; the state starts at 0.

How it is computed (each choice measured on the 2-core CPU against the alternatives):
- sigmoid(z) = (1 + tanh(z / 2)) / 2, so one tanh over all four gates gives i, f, g and o once
  the i, f, o columns of the weights are halved (an exact scaling by a power of two).
- The plain forward pass (no gradient) is Python-unrolled: straight-line code, no loop carries.
- Under differentiation the forward pass is a `lax.scan` that stacks what the backward needs, and
  the backward is a reverse `lax.scan` with one matmul per step, dz @ [w_hh; w_ih]^T, giving the
  recurrent and the input gradient together. The backward is not unrolled: XLA would fuse the
  elementwise cell-gradient chain of all steps into every later step (code quadratic in the
  steps: compiles of many seconds, and slower runs). Weight gradients are formed after the scan
  (XLA drops them when nobody asks).
- No reduction over a leading axis of a large array appears in the gradient: XLA:CPU's are many
  times slower than the same sum written as additions or a matmul.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float


def _halve_ifo(w: jax.Array, hidden: int) -> jax.Array:
    half = jnp.full((hidden,), 0.5, w.dtype)
    return w * jnp.concatenate([half, half, jnp.ones((hidden,), w.dtype), half])


def _scaled(w_ih, w_hh, b):
    hidden = w_hh.shape[0]
    return _halve_ifo(w_ih, hidden), _halve_ifo(w_hh, hidden), _halve_ifo(b, hidden)


def _split(t: jax.Array, hidden: int):
    return tuple(t[..., k * hidden : (k + 1) * hidden] for k in range(4))


def _cell(t, c, hidden):
    """New (h, c) from t = tanh of the halved gates (i/2, f/2, g, o/2) and the old c."""
    ti, tf, tg, to = _split(t, hidden)
    c_new = (0.5 + 0.5 * tf) * c + (0.5 + 0.5 * ti) * tg
    return (0.5 + 0.5 * to) * jnp.tanh(c_new), c_new


def _gate_grads(dh, dc_next, t, c, c_prev, hidden):
    """Gradient w.r.t. the gate pre-activations of one step, and w.r.t. the previous cell state.

    dh, dc_next: gradients reaching h_t and c_t from later steps (dc_next through c_{t+1})."""
    ti, tf, tg, to = _split(t, hidden)
    i, f, o = 0.5 + 0.5 * ti, 0.5 + 0.5 * tf, 0.5 + 0.5 * to
    tc = jnp.tanh(c)
    dc = dc_next + dh * o * (1.0 - tc * tc)
    dz = jnp.concatenate(
        [dc * tg * i * (1.0 - i), dc * c_prev * f * (1.0 - f), dc * i * (1.0 - tg * tg), dh * tc * o * (1.0 - o)],
        axis=-1,
    )
    return dz, dc * f


# -- encoder: sequence in, last hidden state out -----------------------------------------------


def _last_primal(x, w_ih, w_hh, b):
    hidden = w_hh.shape[0]
    wi, wh, bs = _scaled(w_ih, w_hh, b)
    w = jnp.concatenate([wi, wh], 0)
    h = c = jnp.zeros((x.shape[1], hidden), x.dtype)
    for k in range(x.shape[0]):
        # One [x_t, h] @ [w_ih; w_hh] per step: the input projection cannot be hoisted ahead of
        # the recurrence, where all T of them would be alive at once (27 MB at N = 1664).
        gates = x[0] @ wi + bs if k == 0 else jnp.concatenate([x[k], h], -1) @ w + bs
        h, c = _cell(jnp.tanh(gates), c, hidden)
    return h


@jax.custom_vjp
def lstm_last(
    x: Float[Array, "T N n_in"], w_ih: Float[Array, "n_in 4H"], w_hh: Float[Array, "H 4H"], b: Float[Array, "4H"]
) -> Float[Array, "N H"]:
    """The last hidden state of a one-layer LSTM over a time-major sequence."""
    return _last_primal(x, w_ih, w_hh, b)


def _last_fwd(x, w_ih, w_hh, b):
    hidden = w_hh.shape[0]
    wi, wh, bs = _scaled(w_ih, w_hh, b)
    w = jnp.concatenate([wi, wh], 0)

    def step(carry, xt):
        h, c = carry
        t = jnp.tanh(jnp.concatenate([xt, h], -1) @ w + bs)
        h_new, c_new = _cell(t, c, hidden)
        return (h_new, c_new), (h, c, t)

    zeros = jnp.zeros((x.shape[1], hidden), x.dtype)
    (h_last, c_last), (h_prev, c_prev, ts) = jax.lax.scan(step, (zeros, zeros), x)
    return h_last, (x, h_prev, c_prev, ts, c_last, w_ih, w_hh)


def _last_bwd(res, dh_last):
    x, h_prev, c_prev, ts, c_last, w_ih, w_hh = res
    hidden = w_hh.shape[0]
    w_back = jnp.concatenate([w_hh, w_ih], 0).T  # [4H, H + in]: recurrent and input gradient

    def step(carry, xs):
        dh, dc_next, c = carry
        t, cp = xs
        dz, dc_prev = _gate_grads(dh, dc_next, t, c, cp, hidden)
        back = dz @ w_back
        return (back[:, :hidden], dc_prev, cp), (dz, back[:, hidden:])

    init = (dh_last, jnp.zeros_like(dh_last), c_last)
    _, (dzs, dx) = jax.lax.scan(step, init, (ts, c_prev), reverse=True)
    dw_ih = jnp.einsum("tni,tng->ig", x, dzs)
    dw_hh = jnp.einsum("tnh,tng->hg", h_prev, dzs)
    return dx, dw_ih, dw_hh, dzs.sum((0, 1))


lstm_last.defvjp(_last_fwd, _last_bwd)


# -- decoder: the same input at every step, all hidden states out ------------------------------


def _repeat_primal(steps, x, w_ih, w_hh, b):
    hidden = w_hh.shape[0]
    wi, wh, bs = _scaled(w_ih, w_hh, b)
    xw = x @ wi + bs  # the input is the same at every step: projected once
    h = c = jnp.zeros((x.shape[0], hidden), x.dtype)
    hs = []
    for k in range(steps):
        h, c = _cell(jnp.tanh(xw if k == 0 else xw + h @ wh), c, hidden)
        hs.append(h)
    return jnp.stack(hs)


@functools.partial(jax.custom_vjp, nondiff_argnums=(0,))
def lstm_repeat(
    steps: int,
    x: Float[Array, "N n_in"],
    w_ih: Float[Array, "n_in 4H"],
    w_hh: Float[Array, "H 4H"],
    b: Float[Array, "4H"],
) -> Float[Array, "T N H"]:
    """All `steps` hidden states of a one-layer LSTM fed `x` at every step."""
    return _repeat_primal(steps, x, w_ih, w_hh, b)


def _repeat_fwd(steps, x, w_ih, w_hh, b):
    hidden = w_hh.shape[0]
    wi, wh, bs = _scaled(w_ih, w_hh, b)
    xw = x @ wi + bs

    def step(carry, _):
        h, c = carry
        t = jnp.tanh(xw + h @ wh)
        h_new, c_new = _cell(t, c, hidden)
        return (h_new, c_new), (h_new, c, t)

    zeros = jnp.zeros((x.shape[0], hidden), x.dtype)
    (_, c_last), (hs, c_prev, ts) = jax.lax.scan(step, (zeros, zeros), None, length=steps)
    return hs, (x, hs, c_prev, ts, c_last, w_ih, w_hh)


def _repeat_bwd(steps, res, dhs):
    x, hs, c_prev, ts, c_last, w_ih, w_hh = res
    hidden = w_hh.shape[0]
    w_back = w_hh.T

    def step(carry, xs):
        dh_next, dc_next, c, dz_sum = carry
        dh_t, t, cp = xs
        dz, dc_prev = _gate_grads(dh_next + dh_t, dc_next, t, c, cp, hidden)
        return (dz @ w_back, dc_prev, cp, dz_sum + dz), dz

    zeros = jnp.zeros_like(dhs[0])
    init = (zeros, zeros, c_last, jnp.zeros(zeros.shape[:-1] + (4 * hidden,), zeros.dtype))
    (_, _, _, dz_sum), dzs = jax.lax.scan(step, init, (dhs, ts, c_prev), reverse=True)
    h_prev = jnp.concatenate([jnp.zeros_like(hs[:1]), hs[:-1]], 0)
    dw_hh = jnp.einsum("tnh,tng->hg", h_prev, dzs)
    return dz_sum @ w_ih.T, x.T @ dz_sum, dw_hh, dz_sum.sum(0)


lstm_repeat.defvjp(_repeat_fwd, _repeat_bwd)
