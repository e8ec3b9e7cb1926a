"""`diffsense.runtime.uniform` and `normal` draw exactly what `jax.random` draws, for every shape the
project uses and under both threefry modes, so that drawing flat changes no number anywhere; and
the package draws through them only."""

from __future__ import annotations

import re
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffsense
from diffsense import runtime

SHAPES = [(), (7,), (2, 21, 5), (3, 2, 4, 5)]
# Every shape in float64 under the default (partitionable) threefry; float32 and the other mode
# on the many-dimensional shapes, where the two ways of numbering elements could part.
CASES = ([(s, jnp.float64, True) for s in SHAPES]
         + [((3, 2, 4, 5), jnp.float32, True), ((3, 2, 4, 5), jnp.float64, False), ((2, 21, 5), jnp.float32, False)])


def _bits(a):
    a = np.asarray(a)
    return a.view(np.uint64 if a.dtype.itemsize == 8 else np.uint32)


@pytest.mark.parametrize("kind", ["normal", "uniform", "bounded"])
@pytest.mark.parametrize(("shape", "dtype", "partitionable"), CASES)
def test_draws_are_jax_randoms_bit_for_bit(kind, shape, dtype, partitionable):
    # "bounded": uniform between scalar bounds, as the Monte-Carlo uniforms' (eps, 1 - eps)
    eps = jnp.finfo(dtype).eps
    args = (eps, 1.0 - eps) if kind == "bounded" else ()
    name = "uniform" if kind == "bounded" else kind
    with jax.threefry_partitionable(partitionable):
        key = jax.random.PRNGKey(11)
        ours = jax.jit(lambda k: getattr(runtime, name)(k, shape, dtype, *args))(key)
        theirs = jax.jit(lambda k: getattr(jax.random, name)(k, shape, dtype, *args))(key)
    assert ours.shape == shape and ours.dtype == dtype
    np.testing.assert_array_equal(_bits(ours), _bits(theirs))


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_uniform_with_bounds_of_the_draws_shape_is_jax_randoms(dtype):
    """Per-element bounds (the scene variants draw each quantity between its own limits)."""
    key = jax.random.PRNGKey(2)
    lo = jnp.asarray(np.linspace(-3.0, 2.0, 12).reshape(4, 3), dtype)
    hi = lo + jnp.asarray(np.linspace(0.5, 7.0, 12).reshape(4, 3), dtype)
    ours = runtime.uniform(key, (4, 3), dtype, lo, hi)
    np.testing.assert_array_equal(_bits(ours), _bits(jax.random.uniform(key, (4, 3), dtype, lo, hi)))
    assert np.all((np.asarray(ours) >= np.asarray(lo)) & (np.asarray(ours) < np.asarray(hi)))


def test_draws_under_vmap_over_keys_are_jax_randoms():
    """The measurement noise draws one [2, T, V] per variant key under vmap."""
    keys = jax.random.split(jax.random.PRNGKey(9), 6)
    ours = jax.jit(jax.vmap(lambda k: runtime.normal(k, (2, 21, 5), jnp.float64)))(keys)
    theirs = jax.vmap(lambda k: jax.random.normal(k, (2, 21, 5), jnp.float64))(keys)
    np.testing.assert_array_equal(_bits(ours), _bits(theirs))
    assert not np.array_equal(np.asarray(ours[0]), np.asarray(ours[1]))  # the variants' noises differ


def test_the_package_draws_through_the_flat_helpers_only():
    """A shaped `jax.random.uniform` / `normal` elsewhere in the package would compile its draw
    the slow way again (docs/development.md, "Code layout")."""
    root = Path(diffsense.__file__).parent
    found = [f"{path.relative_to(root)}:{i}"
             for path in sorted(root.rglob("*.py")) if path.name != "_random.py"
             for i, line in enumerate(path.read_text().splitlines(), 1)
             if re.search(r"jax\.random\.(uniform|normal)\(", line)]
    assert found == []
