"""`value_and_grad`: jax.value_and_grad of a scalar function of r, in the mode that costs less.

With one number in r (a one-parameter problem: the main job's HFOV), d E / d r needs one tangent,
and `jax.jvp` carries it through the CS-LSTM's forward pass at the price of a larger matmul per
step (`diffsense.predictors.forward_mode`); reverse mode pays a forward pass that keeps its state
plus a backward pass. With more numbers, reverse mode's one backward pass serves them all.
`benchmarks/bench_scaling.py` times both on the main job's evaluation.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp

from diffsense.predictors import forward_mode


def value_and_grad(fn: Callable[..., Any]) -> Callable[..., tuple[Any, Any]]:
    """`jax.value_and_grad(fn)` (with respect to the first argument, a pytree of floats like
    `{"hfov_deg": 45.0}`), computed in forward mode when that argument holds a single number.

    Same values and gradients either way (to float rounding); the gradient has r's structure."""

    def wrapped(r, *args):
        if sum(jnp.size(leaf) for leaf in jax.tree.leaves(r)) != 1:
            return jax.value_and_grad(fn)(r, *args)
        ones = jax.tree.map(jnp.ones_like, r)
        with forward_mode():
            value, slope = jax.jvp(lambda q: fn(q, *args), (r,), (ones,))
        if jnp.shape(value) != ():
            raise TypeError(f"value_and_grad needs a scalar function, got output shape {jnp.shape(value)}")
        return value, jax.tree.map(lambda one: (slope * one).astype(one.dtype), ones)

    return wrapped
