"""The building blocks of CS-LSTM with PyTorch's parameterisation: Linear, LSTM, convolution.

Weights are stored as [in, out] (PyTorch stores [out, in]; the checkpoint reader transposes) and
both LSTM biases are kept, as in `torch.nn.LSTM`, so a published checkpoint maps one to one.
Initialisation is PyTorch's default: uniform in +-1/sqrt(fan_in) (LSTM: +-1/sqrt(hidden)).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
from flax import nnx
from jaxtyping import Array, Float


def _uniform(rngs: nnx.Rngs, shape: tuple[int, ...], fan_in: int) -> jax.Array:
    bound = 1.0 / math.sqrt(fan_in)
    return jax.random.uniform(rngs.params(), shape, jnp.float32, -bound, bound)


def leaky_relu(x: jax.Array) -> jax.Array:
    """LeakyReLU with slope 0.1, the reference's only hidden activation."""
    return jnp.where(x >= 0, x, 0.1 * x)


class Linear(nnx.Module):
    """y = x @ weight + bias; weight [in, out], bias [out]."""

    def __init__(self, n_in: int, n_out: int, *, rngs: nnx.Rngs):
        self.weight = nnx.Param(_uniform(rngs, (n_in, n_out), n_in))
        self.bias = nnx.Param(_uniform(rngs, (n_out,), n_in))

    def __call__(self, x: Float[Array, "... n_in"]) -> Float[Array, "... n_out"]:
        return x @ self.weight[...] + self.bias[...]


class LSTM(nnx.Module):
    """One-layer LSTM, gates stacked (i, f, g, o) along the last axis of w_ih [in, 4H], w_hh [H, 4H].

    gates = x_t @ w_ih + b_ih + h_{t-1} @ w_hh + b_hh; c_t = s(f) c + s(i) tanh(g);
    h_t = s(o) tanh(c_t); h_0 = c_0 = 0.
    """

    def __init__(self, n_in: int, hidden: int, *, rngs: nnx.Rngs):
        self.hidden = hidden
        self.w_ih = nnx.Param(_uniform(rngs, (n_in, 4 * hidden), hidden))
        self.w_hh = nnx.Param(_uniform(rngs, (hidden, 4 * hidden), hidden))
        self.b_ih = nnx.Param(_uniform(rngs, (4 * hidden,), hidden))
        self.b_hh = nnx.Param(_uniform(rngs, (4 * hidden,), hidden))

    def project(self, x: Float[Array, "... n_in"]) -> Float[Array, "... 4H"]:
        """The input part of the gates, x @ w_ih + b_ih + b_hh, for all steps in one matmul."""
        return x @ self.w_ih[...] + (self.b_ih[...] + self.b_hh[...])

    def scan(self, xw: Float[Array, "T N 4H"]) -> Float[Array, "T N H"]:
        """Hidden states of all steps given the projected inputs (time-major)."""
        return lstm_scan(xw, self.w_hh[...])

    def final(self, xw: Float[Array, "T N 4H"]) -> Float[Array, "N H"]:
        """The last hidden state."""
        return lstm_scan(xw, self.w_hh[...])[-1]


def _gate_scale(hidden: int, dtype) -> jax.Array:
    # sigmoid(x) = (1 + tanh(x / 2)) / 2: one tanh over all four gates per step instead of three
    # logistics and a tanh (measured 2-3x faster on this CPU; the same value up to rounding).
    half = jnp.full((hidden,), 0.5, dtype)
    return jnp.concatenate([half, half, jnp.ones((hidden,), dtype), half])


def _forward(xw, w_hh):
    hidden = w_hh.shape[0]
    scale = _gate_scale(hidden, xw.dtype)

    def step(carry, xw_t):
        h, c = carry
        t = jnp.tanh((xw_t + h @ w_hh) * scale)  # tanh of (i/2, f/2, g, o/2)
        i, f, g, o = (t[..., k * hidden : (k + 1) * hidden] for k in range(4))
        c_new = (0.5 + 0.5 * f) * c + (0.5 + 0.5 * i) * g
        h_new = (0.5 + 0.5 * o) * jnp.tanh(c_new)
        return (h_new, c_new), (h_new, t, c)

    zeros = jnp.zeros(xw.shape[1:-1] + (hidden,), xw.dtype)
    # Not unrolled: measured on this CPU, unrolling made compiles 4-13x slower, runs no faster.
    (_, c_last), (hs, ts, cs_prev) = jax.lax.scan(step, (zeros, zeros), xw)
    return hs, (ts, cs_prev, c_last, hs, w_hh)


@jax.custom_vjp
def lstm_scan(xw: Float[Array, "T N 4H"], w_hh: Float[Array, "H 4H"]) -> Float[Array, "T N H"]:
    """One-layer LSTM over time-major projected inputs xw = x @ w_ih + b_ih + b_hh, zero initial
    state; all hidden states. Hand-written backward (back-propagation through time): the
    recurrent step does one [N, 4H] x [4H, H] matmul and the weight gradient is one matmul over
    all steps afterwards (measured 1.3-2x faster than differentiating the scan)."""
    return _forward(xw, w_hh)[0]


def _backward(saved, dhs):
    ts, cs_prev, c_last, hs, w_hh = saved
    hidden = w_hh.shape[0]
    cs = jnp.concatenate([cs_prev[1:], c_last[None]], axis=0)
    hs_prev = jnp.concatenate([jnp.zeros_like(hs[:1]), hs[:-1]], axis=0)

    def step(carry, xs):
        dh_next, dc_next = carry
        dh_t, t, c_prev, c = xs
        ti, tf, tg, to = (t[..., k * hidden : (k + 1) * hidden] for k in range(4))
        i, f, o = 0.5 + 0.5 * ti, 0.5 + 0.5 * tf, 0.5 + 0.5 * to
        dh = dh_next + dh_t
        tc = jnp.tanh(c)
        dc = dc_next + dh * o * (1.0 - tc * tc)
        dgates = jnp.concatenate(
            [dc * tg * i * (1.0 - i), dc * c_prev * f * (1.0 - f), dc * i * (1.0 - tg * tg), dh * tc * o * (1.0 - o)],
            axis=-1,
        )
        return (dgates @ w_hh.T, dc * f), dgates

    zeros = jnp.zeros_like(dhs[0])
    _, dgates = jax.lax.scan(step, (zeros, zeros), (dhs, ts, cs_prev, cs), reverse=True)
    return dgates, jnp.einsum("tnh,tng->hg", hs_prev, dgates)


lstm_scan.defvjp(_forward, _backward)


class FullWidthConv(nnx.Module):
    """Valid 2-D convolution whose kernel spans the whole width W, done as one patch matmul.

    kernel [kh, kw, c_in, c_out] (HWIO; torch's [out, in, kh, kw] transposed), bias [c_out].
    """

    def __init__(self, kh: int, kw: int, c_in: int, c_out: int, *, rngs: nnx.Rngs):
        fan_in = kh * kw * c_in
        self.kernel = nnx.Param(_uniform(rngs, (kh, kw, c_in, c_out), fan_in))
        self.bias = nnx.Param(_uniform(rngs, (c_out,), fan_in))

    def __call__(self, x: Float[Array, "B H W C"]) -> Float[Array, "B Ho c_out"]:
        kh, kw, c_in, c_out = self.kernel.shape
        if x.shape[2] != kw:
            raise ValueError(f"kernel width {kw} must span the input width {x.shape[2]}")
        h_out = x.shape[1] - kh + 1
        patches = jnp.stack([x[:, d : d + h_out] for d in range(kh)], axis=2)  # [B, Ho, kh, W, C]
        flat = patches.reshape(x.shape[0], h_out, kh * kw * c_in)
        return flat @ self.kernel[...].reshape(kh * kw * c_in, c_out) + self.bias[...]
