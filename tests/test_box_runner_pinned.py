"""One BFGS run of the box solve (`diffsense/solve/_box.py`, `_Runner`) and its stopping rules,
by hand.

- J is scaled by 1 / |J(t0)|, less if the first step (the gradient in t) would move t by more
  than first_step_rad: J 4 with |dJ/dt| 1 gives 1/4; with |dJ/dt| 4 (a first step of 1 rad)
  0.5 / 4; J 0.5 gives 2 (no floor at 1).
- Stalled: J fell by at most ftol |J| over its last 3 accepted steps (4 values), ties included.
- A small move: the next trial point moves t by at most atol + rtol max|t|, ties included.
- Tolerances scale by tau / tau_last: the schedule (4, 1/2) at tau 4 multiplies them by 8.
- The value and gradient in t handed to BFGS: scale J(x(t)), whose derivative (central
  differences) is the chain rule through x = lo + w (1 + sin t) / 2.
- A run stops at max_steps, and its soft evaluations stop at the budget.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.solve._box import BoxConfig, _first_scale, _Runner, _small_move, _stalled
from diffsense.solve._box_fns import BoxFunctions
from diffsense.solve._box_space import _Box


@pytest.fixture(autouse=True)
def _x64():
    jax.config.update("jax_enable_x64", True)


def _runner(**config):
    fns = BoxFunctions.from_jax(("range_m",), lambda x, tau: 1.0 + tau * (x[0] - 8.0) ** 2,
                                lambda x: jnp.sqrt(1.0 + (x[0] - 8.0) ** 2))
    box = _Box(np.array([0.0]), np.array([20.0]), 1e-6)
    return _Runner(fns, box, 0.0, BoxConfig(**config)), fns, box


@pytest.mark.parametrize("j, g_max, scale", [(4.0, 1.0, 0.25), (4.0, 4.0, 0.125), (0.5, 0.1, 2.0),
                                             (0.0, 0.0, 1e12)])
def test_first_scale(j, g_max, scale):
    assert _first_scale(j, g_max, 0.5) == scale


@pytest.mark.parametrize("accepted, ftol, stalled", [
    ([1.0, 0.75, 0.625, 0.5], 1.0, True),      # fell 0.5 = ftol |J|: a tie stalls
    ([9.0, 1.0, 0.75, 0.625, 0.5], 1.0, True),  # only the last 4 values count
    ([0.75, 0.625, 0.5], 1.0, False),          # 3 values: too few
    ([1.0, 0.9, 0.8, 0.5], 0.5, False),        # fell 0.5 > 0.25, though 0.2 over the first 2 steps
    ([2.0, 1.9, 1.8, 1.0], 0.9, False),        # fell 1.0 > 0.9 |1.0| (not 0.9 |1.9| or |1.8|)
])
def test_stalled(accepted, ftol, stalled):
    assert _stalled(accepted, ftol) is stalled


def test_small_move():
    assert _small_move(0.5, 2.0, 0.125, 0.25)  # 0.25 + 0.125 * 2: a tie is small
    assert not _small_move(0.5 + 1e-12, 2.0, 0.125, 0.25)


def test_tolerances_scale_with_tau_over_the_last_tau():
    runner, _, _ = _runner(tau_schedule=(4.0, 0.5), rtol=1e-6, atol=2e-6, ftol=1e-4)
    assert runner.tolerances(4.0) == pytest.approx((8e-6, 1.6e-5, 8e-4), rel=1e-15)
    assert runner.tolerances(0.5) == (1e-6, 2e-6, 1e-4)


def test_value_and_gradient_in_t():
    runner, fns, box = _runner()
    t, h = np.array([0.3]), 1e-6
    j, g = runner.j_t(t, 2.0, 3.0)
    x = float(box.x(t)[0])
    assert j == pytest.approx(3.0 * np.sqrt(1.0 + 2.0 * (x - 8.0) ** 2), rel=1e-14)
    fd = (runner.j_t(t + h, 2.0, 3.0)[0] - runner.j_t(t - h, 2.0, 3.0)[0]) / (2 * h)
    assert g.shape == (1,) and g[0] == pytest.approx(fd, rel=1e-8)


def test_a_run_stops_at_max_steps():
    # No tolerance can stop it (all 0: optimistix's test is strict), so only the step cap does.
    runner, _, box = _runner(max_steps=2, ftol=0.0, rtol=0.0, atol=0.0)
    _, steps = runner.run(box.t(np.array([1.0])), 1.0, 10**6)
    assert steps == 2


def test_a_run_stops_when_the_soft_count_reaches_the_budget():
    runner, fns, box = _runner(ftol=0.0, rtol=0.0, atol=0.0)
    _, steps = runner.run(box.t(np.array([1.0])), 1.0, 4)
    # J(t0) for the scale; optimistix's first step evaluates t0 again (memoised: no count),
    # each later step one new trial point.
    assert fns.counts["soft"] == 4 and steps == 4
