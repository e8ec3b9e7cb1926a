"""One temperature level of the continuous solve (`diffsense/solve/_levels.py`), driven directly
with a host gradient that records where it is asked.

- Bisection on a float32 grid with a tolerance (1e-12) far below the grid's spacing near the
  answer (~3e-8): the downhill walk's first steps round back to its start, and the halving
  reaches two neighbouring float32 numbers around the root c of g(r) = r - c. Neither spends
  an evaluation on a point already asked: every point is asked once, and the answer is one
  float32 spacing from c at most.
- The walk's steps from 0.5 upwards (the root at 0.7), in float32 spacings above 0.5 (2^-24):
  steps of 2^k 1e-12 round back to 0.5 until k = 15 (0.55 spacings), then each doubles:
  0.55, 1.1, 2.2, 4.4, 8.8 spacings, on the grid 1, 1, 2, 4, 9: points 1, 2, 4, 8, 17.
- The secant on g(r) = r - 6 over [0, 8] from 0.5 (first probe 2.5) with a budget of 2
  gradient evaluations asks g twice: at 0.5 and 2.5.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.solve._levels import Counted, level_bisection, level_secant


@pytest.fixture(autouse=True)
def _x64():
    jax.config.update("jax_enable_x64", True)


def _recording(c, dtype):
    asked = []

    def value_and_grad(r, tau):
        asked.append(r)
        return 0.0, r - c

    return Counted(lambda r, tau: r, None, dtype, value_and_grad=value_and_grad), asked


@pytest.mark.parametrize("c", [1 / 3, 2 / 3, 0.1, 0.3, 0.45])
def test_bisection_on_a_float32_grid_asks_no_point_twice(c):
    counted, asked = _recording(c, jnp.float32)
    (r, bound), evaluations, converged = level_bisection(counted, 0.5, 1.0, 0.0, 1.0, 1e-12, 200)
    assert len(asked) == len(set(asked)) == evaluations < 200
    assert bound == 0 and converged
    assert r == float(np.float32(r)) and abs(r - c) <= float(np.spacing(np.float32(c)))


def test_the_walk_doubles_its_step_from_the_first_that_leaves_the_start():
    counted, asked = _recording(0.7, jnp.float32)
    level_bisection(counted, 0.5, 1.0, 0.0, 1.0, 1e-12, 200)
    assert [(r - 0.5) / 2.0**-24 for r in asked[:6]] == [0.0, 1.0, 2.0, 4.0, 8.0, 17.0]


def test_secant_stops_at_its_budget():
    counted, asked = _recording(6.0, jnp.float64)
    y, n, bound, done = level_secant(counted, 0.5, 1.0, 0.0, 8.0, 2.0, 1e-9, 20, 2)
    assert asked == [0.5, 2.5] and n == 2 and not done
