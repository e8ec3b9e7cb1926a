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

from diffsense import runtime
from diffsense.predictors._lstm import lstm_last, lstm_repeat


def _uniform(rngs: nnx.Rngs, shape: tuple[int, ...], fan_in: int) -> jax.Array:
    bound = 1.0 / math.sqrt(fan_in)
    return runtime.uniform(rngs.params(), shape, jnp.float32, -bound, bound)


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

    def _weights(self):
        return self.w_ih[...], self.w_hh[...], self.b_ih[...] + self.b_hh[...]

    def final(self, x: Float[Array, "T N d"], embedding: Linear | None = None) -> Float[Array, "N H"]:
        """The last hidden state of each sequence (time-major input); with `embedding`, the LSTM's
        input is leaky_relu(embedding(x_t)), formed inside the recurrence."""
        emb = None if embedding is None else (embedding.weight[...], embedding.bias[...])
        return lstm_last(x, *self._weights(), emb=emb)

    def repeated(self, x: Float[Array, "N n_in"], steps: int) -> Float[Array, "T N H"]:
        """Hidden states of `steps` steps whose input is `x` at every step (the decoder's case:
        the input is projected once, and its gradient is the sum over steps)."""
        return lstm_repeat(steps, x, *self._weights())


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
