"""`jax.random` draws of any shape, made as one flat draw and reshaped: the same numbers, compiled
in a fraction of the time.

JAX numbers the elements of a threefry draw by their row-major index (in its partitionable mode,
the default, built from one 64-bit iota per dimension; in the other by drawing flat and
reshaping), and the conversion of bits to uniform or normal numbers is element by element. So `uniform(key, (a, b, c))` is `jax.random.uniform(key, (a * b * c,))`
reshaped, bit for bit (`tests/test_random.py` checks it shape by shape). XLA:CPU compiles the
partitionable index of a many-dimensional shape slowly: `python benchmarks/bench_random.py`
prints the compile times of both forms.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, PRNGKeyArray


def uniform(key: PRNGKeyArray, shape: Sequence[int], dtype=float, minval: ArrayLike = 0.0,
            maxval: ArrayLike = 1.0) -> Array:
    """`jax.random.uniform(key, shape, dtype, minval, maxval)`, bit for bit; `minval` and
    `maxval` broadcast to `shape`."""
    shape = tuple(shape)
    size = math.prod(shape)
    lo, hi = (jnp.broadcast_to(jnp.asarray(v, dtype), shape).reshape(size) for v in (minval, maxval))
    return jax.random.uniform(key, (size,), dtype, lo, hi).reshape(shape)


def normal(key: PRNGKeyArray, shape: Sequence[int], dtype=float) -> Array:
    """`jax.random.normal(key, shape, dtype)`, bit for bit."""
    shape = tuple(shape)
    return jax.random.normal(key, (math.prod(shape),), dtype).reshape(shape)
