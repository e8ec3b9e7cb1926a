"""The LSTM recurrences of CS-LSTM with a hand-written backward pass (and a forward mode).

`lstm_last(x, w_ih, w_hh, b, emb)`: the encoder, a time-major sequence [T, N, d] -> the last
hidden state [N, H]; with emb = (emb_w, emb_b) the LSTM's input is leaky_relu(x_t @ emb_w + emb_b),
formed inside the step (CS-LSTM's ip_emb of the (x, y) history: no [T, N, in] array).
`lstm_repeat(steps, x, w_ih, w_hh, b)`: the decoder, whose input [N, in] is the same at every
step -> all hidden states [T, N, H]; its input is projected once, and the gradient of the
projection is the sum of the per-step gate gradients. `b` is b_ih + b_hh; the state starts at
zero. Both are differentiable in every argument: in reverse mode (`jax.custom_vjp`, below) by
default, in forward mode (`jax.jvp`) while traced inside `forward_mode()` (`_lstm_forward.py`).

How it is computed (each choice measured on the 2-core CPU against the alternatives; see
benchmarks/bench_lstm.py):
- One tanh over all four gates (the cell and `unrolled`, the primal, are in `_lstm_cell.py`).
- Encoder gates come from one [x_t, h] @ [w_ih; w_hh] per step. This also keeps the T input
  projections from being hoisted ahead of the recurrence, where all would be alive at once.
- The plain forward pass (no gradient) is Python-unrolled: straight-line code, no loop carries.
- Under differentiation the forward pass is a `lax.scan` that keeps h_{t-1}, c_{t-1} (and the
  gates, when they are small) and the backward pass a reverse `lax.scan` with one matmul per step,
  dz @ [w_hh; w_ih]^T, giving the recurrent and the input gradient together. Gates that would
  take more than `REMAT_BYTES` are recomputed in the backward pass instead: memory that is not
  written is faster than a matmul here. The backward pass is not unrolled: XLA then fuses the
  elementwise cell-gradient chain of all earlier steps into every step (code quadratic in T).
- No reduction over a leading axis of a large array appears in the gradient: XLA:CPU's are many
  times slower than the same sum written as additions or carried through the scan.
Weight gradients (training) are formed after the scan; XLA drops them when nobody asks.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from diffsense.predictors._lstm_cell import (
    Gates,
    cell_step,
    leaky_relu,
    product,
    split_gates,
    unrolled,
)
from diffsense.predictors._lstm_forward import forward_mode_active, lstm_forward

__all__ = ["leaky_relu", "lstm_last", "lstm_repeat"]

REMAT_BYTES = 16 * 2**20  # recompute the gates in the backward pass above this size [bytes]


def _gate_grads(dh, dc_next, t, c, c_prev, hidden):
    """Gradient w.r.t. the gate pre-activations of a step (from dL/dh_t and the dL/dc_t that comes
    through c_{t+1}), and the part of dL/dc_{t-1} that goes through c_t."""
    ti, tf, tg, to = split_gates(t, hidden)
    i, f = 0.5 + 0.5 * ti, 0.5 + 0.5 * tf
    tc = jnp.tanh(c)
    dc = dc_next + dh * (0.5 + 0.5 * to) * (1.0 - tc * tc)
    # d sigmoid(z) / dz = (1 - tanh(z / 2)^2) / 4
    dz = jnp.concatenate(
        [
            dc * tg * 0.25 * (1.0 - ti * ti),
            dc * c_prev * 0.25 * (1.0 - tf * tf),
            dc * i * (1.0 - tg * tg),
            dh * tc * 0.25 * (1.0 - to * to),
        ],
        axis=-1,
    )
    return dz, dc * f


def _remat(steps, x, hidden) -> bool:
    return steps * x.shape[-2] * 4 * hidden * x.dtype.itemsize > REMAT_BYTES


def _fwd(steps, last_only, x, emb, w_ih, w_hh, b):
    gates, remat = Gates(x, emb, w_ih, w_hh, b), _remat(steps, x, w_hh.shape[0])

    def step(carry, xt):
        h, c = carry
        t = gates(xt, h)
        h_new, c_new = cell_step(t, c, gates.hidden)
        return (h_new, c_new), (None if last_only else h_new, h, c, None if remat else t)

    zeros = jnp.zeros((x.shape[-2], gates.hidden), x.dtype)
    (h_last, c_last), (hs, h_prev, c_prev, ts) = jax.lax.scan(
        step, (zeros, zeros), None if gates.repeated else x, length=steps
    )
    return h_last if last_only else hs, (x, emb, h_prev, c_prev, ts, c_last, w_ih, w_hh, b)


def _bwd(steps, last_only, res, dhs):
    x, emb, h_prev, c_prev, ts, c_last, w_ih, w_hh, b = res
    gates = Gates(x, emb, w_ih, w_hh, b)
    hidden, repeated = gates.hidden, gates.repeated
    w_back = w_hh.T if repeated else jnp.concatenate([w_hh, w_ih], 0).T  # [4H, H (+ in)]

    def step(carry, xs):
        dh_next, dc_next, c, dz_sum = carry
        dh_t, xt, hp, cp, t = xs
        t = gates(xt, hp) if t is None else t
        dz, dc_prev = _gate_grads(dh_next if dh_t is None else dh_next + dh_t, dc_next, t, c, cp, hidden)
        back = product(dz, w_back)
        if repeated:
            return (back, dc_prev, cp, dz_sum + dz), (dz, None, None)
        d_in = back[:, hidden:]  # dL/d(LSTM input at t)
        if emb is None:
            return (back[:, :hidden], dc_prev, cp, None), (dz, d_in, None)
        d_pre = jnp.where(gates.pre_embedding(xt) >= 0, d_in, 0.1 * d_in)
        return (back[:, :hidden], dc_prev, cp, None), (dz, d_pre @ emb[0].T, d_pre)

    zeros = jnp.zeros_like(c_last)
    dz0 = jnp.zeros(zeros.shape[:-1] + (4 * hidden,), zeros.dtype) if repeated else None
    # Only the last state's gradient (the encoder): it starts the carry, no [T, N, H] of zeros.
    init = (dhs, zeros, c_last, dz0) if last_only else (zeros, zeros, c_last, dz0)
    xs = (None if last_only else dhs, None if repeated else x, None if ts is not None else h_prev, c_prev, ts)
    (_, _, _, dz_sum), (dzs, dx, d_pre) = jax.lax.scan(step, init, xs, reverse=True)
    # A weight's cotangent in its own dtype (a bfloat16 matrix's, for the "bfloat16" products)
    dw_hh = jnp.einsum("tnh,tng->hg", h_prev, dzs).astype(w_hh.dtype)
    if repeated:
        return product(dz_sum, w_ih.T), None, (x.T @ dz_sum).astype(w_ih.dtype), dw_hh, dz_sum.sum(0)
    inputs = x if emb is None else jax.vmap(gates.input)(x)
    d_emb = None if emb is None else (jnp.einsum("tnd,tni->di", x, d_pre), d_pre.sum((0, 1)))
    return dx, d_emb, jnp.einsum("tni,tng->ig", inputs, dzs).astype(w_ih.dtype), dw_hh, dzs.sum((0, 1))


@functools.partial(jax.custom_vjp, nondiff_argnums=(0, 1))
def _lstm(steps, last_only, x, emb, w_ih, w_hh, b):
    hs = unrolled(steps, x, emb, w_ih, w_hh, b)
    return hs[-1] if last_only else jnp.stack(hs)


_lstm.defvjp(_fwd, _bwd)


def _recurrence():
    """The differentiation rule in force while tracing: forward mode inside `forward_mode()`."""
    return lstm_forward if forward_mode_active() else _lstm


def lstm_repeat(
    steps: int,
    x: Float[Array, "N n_in"],
    w_ih: Float[Array, "n_in 4H"],
    w_hh: Float[Array, "H 4H"],
    b: Float[Array, "4H"],
) -> Float[Array, "T N H"]:
    """All `steps` hidden states of a one-layer LSTM fed `x` at every step."""
    return _recurrence()(steps, False, x, None, w_ih, w_hh, b)


def lstm_last(
    x: Float[Array, "T N d"],
    w_ih: Float[Array, "n_in 4H"],
    w_hh: Float[Array, "H 4H"],
    b: Float[Array, "4H"],
    emb: tuple[Float[Array, "d n_in"], Float[Array, "n_in"]] | None = None,
) -> Float[Array, "N H"]:
    """The last hidden state of a one-layer LSTM over a time-major sequence; with `emb` =
    (emb_w, emb_b) the LSTM's input is leaky_relu(x_t @ emb_w + emb_b) (slope 0.1)."""
    return _recurrence()(x.shape[0], True, x, emb, w_ih, w_hh, b)
