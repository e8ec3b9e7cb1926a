"""Kills the survivors of a third solve sample (seed 3, 140 mutants at 8d06eed; docs/mutation.md):
the box solve's reported gradient of E and bounds, the bracketed secant's stop at the float
resolution of its bracket, the dense check's explanation of a miss, and the evaluator's dtypes
for an objective that runs in float32."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

from diffsense.solve import Evaluator
from diffsense.solve._box import BoxConfig, box_solve
from diffsense.solve._box_fns import BoxFunctions
from diffsense.solve._bracketed import BracketedSecant
from diffsense.solve._dense import DenseGrid, basin_check
from tests.test_evaluator_pinned import Bowl


@pytest.fixture(autouse=True)
def _x64():
    jax.config.update("jax_enable_x64", True)


def test_box_answer_on_a_bound_reports_the_gradient_of_e_and_the_bounds():
    # E_soft^2(x, tau) = 1 + tau + (x - 8)^2 / 100 over [10, 20]: the minimum is on the lower
    # bound. At x = 10 and tau = 1: E_soft = sqrt(2.04) m, dE^2/dx = 2 * 2 / 100 = 0.04 m^2,
    # so dE/dx = 0.04 / (2 sqrt(2.04)) = 0.0140028 m per m.
    fns = BoxFunctions.from_jax(("range_m",), lambda x, tau: 1.0 + tau + (x[0] - 8.0) ** 2 / 100.0,
                                lambda x: jnp.sqrt(1.0 + (x[0] - 8.0) ** 2 / 100.0))
    result = box_solve(fns, {"range_m": (10.0, 20.0)}, BoxConfig(tau_schedule=(2.0, 1.0)))
    assert result.x_star == {"range_m": 10.0}
    assert result.on_bound == {"range_m": "lower"}
    assert result.bounds == {"range_m": (10.0, 20.0)}
    assert result.E_soft == pytest.approx(math.sqrt(2.04), rel=1e-12)
    assert result.gradient_E["range_m"] == pytest.approx(0.04 / (2.0 * math.sqrt(2.04)), rel=1e-9)


def test_bracketed_secant_stops_at_the_float_resolution_of_its_bracket():
    # g jumps from -1 to +1 at c with no zero, on a bracket near 1e6 where neighbouring floats
    # are 1.2e-10 apart. Asked for xtol 0, the secant can only stop when the bracket is within
    # 4 eps |r| (8.9e-10) of closing; the halving Illinois steps get there in tens of steps,
    # far short of the 300 evaluations allowed.
    c = 1e6 + 3.3

    def g(y, args):
        return jnp.where(y < c, -1.0 - (c - y), 1.0 + (y - c))

    sol = optx.root_find(g, BracketedSecant(rtol=0.0, atol=0.0), jnp.asarray(1e6 + 0.5),
                         options=dict(lower=1e6, upper=1e6 + 10.0, max_evaluations=300),
                         max_steps=400, throw=False)
    resolution = 4.0 * np.finfo(np.float64).eps * (1e6 + 10.0)
    assert int(sol.stats["num_steps"]) < 100
    assert abs(float(sol.value) - c) <= resolution


def test_basin_check_says_when_the_steps_are_coarser_than_the_basin():
    # E_hard = 3 1 3 2 3 at r = 0..4: the best point r = 1, its basin [0, 2]; r* = 3.5 (E 2 m)
    # lies outside it, and the bracket (3, 4) does not hold r = 1.
    dense = DenseGrid(r=np.arange(5.0), E_hard=np.array([3.0, 1.0, 3.0, 2.0, 3.0]), evaluations=5, wall_s=0.0)
    assert basin_check(dense, 3.5, 2.0, bracket=(3.0, 4.0)) == (
        "r*=3.5 lies outside the basin [0, 2] of the best dense point r=1 (E_hard=1 m); "
        "E_hard(r*)=2 m is worse by 1 m: the stepped sweep's best step does not bracket the dense "
        "optimum (the steps are coarser than the basin)"
    )


class Float32Bowl(Bowl):
    """The bowl in float32, whose soft E^2 gains 100 m^2 if tau does not arrive in float32."""

    @property
    def dtype(self):
        return jnp.float32

    def e2(self, x, tau):
        return (x - 3.0) ** 2 + tau / 4.0 + (0.0 if tau.dtype == jnp.float32 else 100.0)


def test_a_float32_objective_gets_its_temperature_in_float32():
    v, g = Evaluator(Float32Bowl()).value_and_grad(4.0, 1.0)
    assert v == 1.25 and g.tolist() == [2.0]  # (4 - 3)^2 + 1/4, 2 (4 - 3)


def test_solver_functions_in_float32():
    e2_soft, _ = Evaluator(Bowl()).solver_fns(jnp.float32)
    r, tau = jnp.float32(4.0), jnp.float32(1.0)
    value, slope = jax.jvp(lambda x: e2_soft(x, tau), (r,), (jnp.float32(1.0),))
    assert value.dtype == slope.dtype == jnp.float32
    assert (float(value), float(slope)) == (1.25, 2.0)
