"""The LSTM recurrences of CS-LSTM with a hand-written backward pass.

`lstm_last(x, w_ih, w_hh, b, emb)`: the encoder, a time-major sequence [T, N, d] -> the last
hidden state [N, H]; with emb = (emb_w, emb_b) the LSTM's input is leaky_relu(x_t @ emb_w + emb_b),
formed inside the step (CS-LSTM's ip_emb of the (x, y) history: no [T, N, in] array).
`lstm_repeat(steps, x, w_ih, w_hh, b)`: the decoder, whose input [N, in] is the same at every
step -> all hidden states [T, N, H]; its input is projected once, and the gradient of the
projection is the sum of the per-step gate gradients. `b` is b_ih + b_hh; the state starts at
zero. Both are differentiable in every argument (reverse mode only: `jax.custom_vjp`).

How it is computed (each choice measured on the 2-core CPU against the alternatives; see
benchmarks/bench_lstm.py):
- sigmoid(z) = (1 + tanh(z / 2)) / 2, so one tanh over all four gates gives i, f, g and o once
  the i, f, o columns of the weights are halved (an exact scaling by a power of two).
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

REMAT_BYTES = 16 * 2**20  # recompute the gates in the backward pass above this size [bytes]


def _halve_ifo(w: jax.Array, hidden: int) -> jax.Array:
    half = jnp.full((hidden,), 0.5, w.dtype)
    return w * jnp.concatenate([half, half, jnp.ones((hidden,), w.dtype), half])


def _split(t: jax.Array, hidden: int):
    return tuple(t[..., k * hidden : (k + 1) * hidden] for k in range(4))


def _cell(t, c, hidden):
    """New (h, c) from t = tanh of the halved gates (i/2, f/2, g, o/2) and the old c."""
    ti, tf, tg, to = _split(t, hidden)
    c_new = (0.5 + 0.5 * tf) * c + (0.5 + 0.5 * ti) * tg
    return (0.5 + 0.5 * to) * jnp.tanh(c_new), c_new


def _gate_grads(dh, dc_next, t, c, c_prev, hidden):
    """Gradient w.r.t. the gate pre-activations of a step (from dL/dh_t and the dL/dc_t that comes
    through c_{t+1}), and the part of dL/dc_{t-1} that goes through c_t."""
    ti, tf, tg, to = _split(t, hidden)
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


def leaky_relu(x: jax.Array) -> jax.Array:
    """LeakyReLU with slope 0.1, the reference's only hidden activation."""
    return jnp.where(x >= 0, x, 0.1 * x)


class _Gates:
    """gates(x_t, h) = tanh of the halved pre-activations. `x` is [T, N, d] (a sequence) or [N, in]
    (repeated). A sequence may come with an embedding (emb_w [d, in], emb_b [in]): the LSTM input
    is then leaky_relu(x_t @ emb_w + emb_b), formed inside the step (d = 2 for CS-LSTM's (x, y):
    two multiply-adds, no [T, N, in] array)."""

    def __init__(self, x, emb, w_ih, w_hh, b):
        hidden = w_hh.shape[0]
        self.hidden, self.repeated, self.emb = hidden, x.ndim == 2, emb
        wi, self.wh, bs = (_halve_ifo(a, hidden) for a in (w_ih, w_hh, b))
        if self.repeated:
            self.xw = x @ wi + bs  # the same input at every step: projected once
        else:
            self.w, self.bs, self.n_in = jnp.concatenate([wi, self.wh], 0), bs, wi.shape[0]

    def pre_embedding(self, xt):
        emb_w, emb_b = self.emb
        return sum(xt[..., k : k + 1] * emb_w[k] for k in range(emb_w.shape[0])) + emb_b

    def input(self, xt):
        return xt if self.emb is None else leaky_relu(self.pre_embedding(xt))

    def __call__(self, xt, h):
        if self.repeated:
            return jnp.tanh(self.xw + h @ self.wh)
        if h is None:  # h = 0: no recurrent matmul
            return jnp.tanh(self.input(xt) @ self.w[: self.n_in] + self.bs)
        return jnp.tanh(jnp.concatenate([self.input(xt), h], -1) @ self.w + self.bs)


def _primal(steps, x, emb, w_ih, w_hh, b):
    gates = _Gates(x, emb, w_ih, w_hh, b)
    h = c = jnp.zeros((x.shape[-2], gates.hidden), x.dtype)
    hs = []
    for k in range(steps):
        if gates.repeated:
            t = jnp.tanh(gates.xw) if k == 0 else gates(None, h)
        else:
            t = gates(x[k], h if k else None)
        h, c = _cell(t, c, gates.hidden)
        hs.append(h)
    return hs


def _remat(steps, x, hidden) -> bool:
    return steps * x.shape[-2] * 4 * hidden * x.dtype.itemsize > REMAT_BYTES


def _fwd(steps, last_only, x, emb, w_ih, w_hh, b):
    gates, remat = _Gates(x, emb, w_ih, w_hh, b), _remat(steps, x, w_hh.shape[0])

    def step(carry, xt):
        h, c = carry
        t = gates(xt, h)
        h_new, c_new = _cell(t, c, gates.hidden)
        return (h_new, c_new), (None if last_only else h_new, h, c, None if remat else t)

    zeros = jnp.zeros((x.shape[-2], gates.hidden), x.dtype)
    (h_last, c_last), (hs, h_prev, c_prev, ts) = jax.lax.scan(
        step, (zeros, zeros), None if gates.repeated else x, length=steps
    )
    return h_last if last_only else hs, (x, emb, h_prev, c_prev, ts, c_last, w_ih, w_hh, b)


def _bwd(steps, last_only, res, dhs):
    x, emb, h_prev, c_prev, ts, c_last, w_ih, w_hh, b = res
    gates = _Gates(x, emb, w_ih, w_hh, b)
    hidden, repeated = gates.hidden, gates.repeated
    w_back = w_hh.T if repeated else jnp.concatenate([w_hh, w_ih], 0).T  # [4H, H (+ in)]

    def step(carry, xs):
        dh_next, dc_next, c, dz_sum = carry
        dh_t, xt, hp, cp, t = xs
        t = gates(xt, hp) if t is None else t
        dz, dc_prev = _gate_grads(dh_next if dh_t is None else dh_next + dh_t, dc_next, t, c, cp, hidden)
        back = dz @ w_back
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
    dw_hh = jnp.einsum("tnh,tng->hg", h_prev, dzs)
    if repeated:
        return dz_sum @ w_ih.T, None, x.T @ dz_sum, dw_hh, dz_sum.sum(0)
    inputs = x if emb is None else jax.vmap(gates.input)(x)
    d_emb = None if emb is None else (jnp.einsum("tnd,tni->di", x, d_pre), d_pre.sum((0, 1)))
    return dx, d_emb, jnp.einsum("tni,tng->ig", inputs, dzs), dw_hh, dzs.sum((0, 1))


@functools.partial(jax.custom_vjp, nondiff_argnums=(0, 1))
def _lstm(steps, last_only, x, emb, w_ih, w_hh, b):
    hs = _primal(steps, x, emb, w_ih, w_hh, b)
    return hs[-1] if last_only else jnp.stack(hs)


_lstm.defvjp(_fwd, _bwd)


def lstm_repeat(
    steps: int,
    x: Float[Array, "N n_in"],
    w_ih: Float[Array, "n_in 4H"],
    w_hh: Float[Array, "H 4H"],
    b: Float[Array, "4H"],
) -> Float[Array, "T N H"]:
    """All `steps` hidden states of a one-layer LSTM fed `x` at every step."""
    return _lstm(steps, False, x, None, w_ih, w_hh, b)


def lstm_last(
    x: Float[Array, "T N d"],
    w_ih: Float[Array, "n_in 4H"],
    w_hh: Float[Array, "H 4H"],
    b: Float[Array, "4H"],
    emb: tuple[Float[Array, "d n_in"], Float[Array, "n_in"]] | None = None,
) -> Float[Array, "N H"]:
    """The last hidden state of a one-layer LSTM over a time-major sequence; with `emb` =
    (emb_w, emb_b) the LSTM's input is leaky_relu(x_t @ emb_w + emb_b) (slope 0.1)."""
    return _lstm(x.shape[0], True, x, emb, w_ih, w_hh, b)
