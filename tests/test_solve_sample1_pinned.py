"""The survivors of the solve package's second mutation sample (seed 1, docs/mutation.md), each
pinned to a value worked by hand.

- A box solve whose E is identically zero: J = E + 0.5 x over [1, 3] has its minimum on the
  lower bound x = 1, where dJ/dx = 0.5 and dE/dx = 0 (E does not depend on x at all).
- The result reports the temperatures it used, as floats.
- BoxConfig refuses a negative or infinite cost weight and a temperature that is negative or
  infinite (NaN, zero and an increasing schedule were refused by earlier tests).
- A soft evaluation is recorded with E = sqrt(E^2): 1.5 m for E^2 = 2.25 m^2, 0 for a rounding
  negative E^2.
- The continuation's stall test: the runner documents its tolerances as scaled by
  tau / tau_last. So a level at tau 4 of the schedule (4, 1) with ftol, rtol, atol equals a level
  at tau 1 of the schedule (1,) with 4 ftol, 4 rtol, 4 atol when E does not depend on tau: the
  same steps to the same point. The bowl 1 + (x - 8)^4 / 1000 from x = 1 (rtol = atol = 0, so
  only the stall test stops it) stalls after 6 steps at ftol 1e-4 (scaled: 4e-4), and runs
  8 steps at a quarter of that.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.runtime._errors import InputError
from diffsense.solve._box import BoxConfig, _Runner, box_solve
from diffsense.solve._box_space import _Box
from diffsense.solve._box_fns import BoxFunctions


@pytest.fixture(autouse=True)
def _x64():
    jax.config.update("jax_enable_x64", True)


def test_zero_e_has_zero_gradient_of_e_at_the_answer():
    fns = BoxFunctions.from_jax(("range_m",), lambda x, tau: 0.0 * x[0], lambda x: 0.0 * x[0],
                                cost=lambda x: x[0])
    result = box_solve(fns, {"range_m": (1.0, 3.0)}, BoxConfig(cost_weight=0.5, tau_schedule=(2.0, 1.0)))
    assert result.x_star == {"range_m": 1.0} and result.on_bound == {"range_m": "lower"}
    assert result.E_soft == 0.0 and result.E_hard == 0.0 and result.J_star == pytest.approx(0.5, abs=1e-12)
    assert result.gradient == pytest.approx({"range_m": 0.5}, abs=1e-12)
    assert result.gradient_E == {"range_m": 0.0}


def test_result_reports_the_schedule_as_floats():
    fns = BoxFunctions.from_jax(("range_m",), lambda x, tau: 1.0 + (x[0] - 2.0) ** 2, lambda x: 1.0 + 0.0 * x[0])
    result = box_solve(fns, {"range_m": (1.0, 3.0)}, BoxConfig(tau_schedule=(3, 1), starts=1, max_steps=2))
    assert result.tau_schedule == (3.0, 1.0)
    assert all(type(t) is float for t in result.tau_schedule)


@pytest.mark.parametrize("weight", [-1.0, math.inf, math.nan])
def test_box_config_refuses_a_negative_or_infinite_cost_weight(weight):
    with pytest.raises(InputError, match="cost_weight"):
        BoxConfig(cost_weight=weight)


@pytest.mark.parametrize("schedule", [(1.0, -1.0), (math.inf, 1.0), (2.0, 0.0)])
def test_box_config_refuses_a_negative_or_infinite_temperature(schedule):
    with pytest.raises(InputError, match="positive numbers"):
        BoxConfig(tau_schedule=schedule)


def test_soft_evaluation_is_recorded_with_e_not_e2():
    values = {2.0: 2.25, 3.0: -1e-18}
    fns = BoxFunctions(("range_m",), lambda x, tau: (values[float(x[0])], np.zeros(1)), lambda x: 0.0)
    fns.e2_soft([2.0], 1.0)
    fns.e2_soft([3.0], 0.5)
    assert [(e.kind, e.x, e.tau, e.value) for e in fns.history] == [
        ("soft", (2.0,), 1.0, 1.5), ("soft", (3.0,), 0.5, 0.0)]


def _quartic_level(schedule, tau, ftol):
    fns = BoxFunctions.from_jax(("range_m",), lambda x, tau: 1.0 + (x[0] - 8.0) ** 4 / 1000.0,
                                lambda x: jnp.sqrt(1.0 + (x[0] - 8.0) ** 4 / 1000.0))
    box = _Box(np.array([0.0]), np.array([20.0]), 1e-6)
    config = BoxConfig(tau_schedule=schedule, ftol=ftol, rtol=0.0, atol=0.0, max_steps=60)
    t, steps = _Runner(fns, box, 0.0, config).run(box.t(np.array([1.0])), tau, 10**6)
    return float(box.x(t)[0]), steps


def test_stall_tolerance_is_scaled_by_tau_over_the_last_tau():
    early = _quartic_level((4.0, 1.0), 4.0, 1e-4)
    last = _quartic_level((1.0,), 1.0, 4e-4)
    assert early == last
    assert early[1] == 6  # stalled, far below max_steps
    # a quarter of the tolerance stalls later: the stall test, not a step cap, ended the level
    assert _quartic_level((1.0,), 1.0, 1e-4)[1] > early[1]
