"""The textbook LSTM (logistic gates, `lax.scan`): JAX's own autodiff of it is the reference the
CS-LSTM recurrences' hand-written derivatives are tested against."""

from __future__ import annotations

import jax
import jax.numpy as jnp


def textbook_lstm(xs, w_ih, w_hh, b):
    """The LSTM with logistic gates, one step at a time; xs [T, N, in] -> all h [T, N, H]."""

    def step(carry, x):
        h, c = carry
        i, f, g, o = jnp.split(x @ w_ih + h @ w_hh + b, 4, axis=-1)
        c = jax.nn.sigmoid(f) * c + jax.nn.sigmoid(i) * jnp.tanh(g)
        h = jax.nn.sigmoid(o) * jnp.tanh(c)
        return (h, c), h

    zeros = jnp.zeros((xs.shape[1], w_hh.shape[0]), xs.dtype)
    return jax.lax.scan(step, (zeros, zeros), xs)[1]
