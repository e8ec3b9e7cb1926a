"""What a box solve reports (`diffsense/solve/_box.py`), on one-parameter problems worked by hand.

- No soft budget (max_soft 0): no BFGS step at any level, each start ends where it began (the
  k-th best point of the hard sample), and the only soft evaluations are each start's J_soft at
  the last temperature (the answer is one of them).
- Ties on the hard objective: a soft bowl at 8 over [0, 20] with E_hard 1 m within 0.2 of 8 and
  2 m elsewhere (no sample point is that close); every level of every start lands there, and the
  answer is the first candidate to reach 1 m: start 0 at the first temperature.
- A minimum on the lower bound: E_soft^2 = 1/4 + tau (x - 8)^2 / 100 over [10, 20] ends at x = 10,
  where at the last temperature (tau 1) E_soft = sqrt(0.29) m, dE^2/dx = 0.04 m, so
  dE/dx = 0.04 / (2 sqrt(0.29)) (at tau 2 it would be 0.08 / (2 sqrt(0.33))).
- A second solve on the same functions evaluates nothing new and says so.
- A start outside the box begins on its bound; the Pareto front by hand.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.solve._box import BoxConfig, box_solve
from diffsense.solve._box_fns import BoxFunctions
from diffsense.solve._box_space import halton
from diffsense.solve._pareto import _pareto_front

BOUNDS = {"range_m": (0.0, 20.0)}
EXACT = BoxConfig(ftol=0.0)


@pytest.fixture(autouse=True)
def _x64():
    jax.config.update("jax_enable_x64", True)


def _flat_bowl():
    return BoxFunctions.from_jax(("range_m",), lambda x, tau: 1.0 + tau + (x[0] - 8.0) ** 2 / 100.0,
                                 lambda x: jnp.sqrt(1.0 + (x[0] - 8.0) ** 2 / 100.0))


def test_without_a_soft_budget_each_start_stays_on_its_sample_point():
    fns = _flat_bowl()
    result = box_solve(fns, BOUNDS, BoxConfig(max_soft=0, starts=2))
    sample = sorted((e.value, e.x[0]) for e in result.history if e.kind == "hard")
    assert len(sample) == 4  # 2 d + 2 points, each start's answers among them
    for k, start in enumerate(result.starts):
        assert start.steps == (0, 0, 0)
        assert start.x0 == start.x == {"range_m": sample[k][1]}
    assert result.counts["soft"] == 2 and result.x_star == {"range_m": sample[0][1]}


def test_ties_on_the_hard_objective_go_to_the_first_candidate():
    fns = BoxFunctions.from_jax(("range_m",), lambda x, tau: 1.0 + (x[0] - 8.0) ** 2,
                                lambda x: jnp.where(jnp.abs(x[0] - 8.0) < 0.2, 1.0, 2.0))
    result = box_solve(fns, BOUNDS, EXACT)
    assert min(e.value for e in result.history[:4]) == 2.0  # the sample never reaches 1 m
    assert [s.J_hard for s in result.starts] == [1.0, 1.0]
    assert result.J_star == 1.0 and result.source == "start 0 tau 4"


def test_gradient_and_e_soft_at_a_lower_bound_are_those_of_the_last_temperature():
    fns = BoxFunctions.from_jax(("range_m",), lambda x, tau: 0.25 + tau * (x[0] - 8.0) ** 2 / 100.0,
                                lambda x: jnp.sqrt(0.25 + (x[0] - 8.0) ** 2 / 100.0))
    result = box_solve(fns, {"range_m": (10.0, 20.0)}, BoxConfig(tau_schedule=(4.0, 2.0, 1.0)))
    assert result.x_star == {"range_m": 10.0} and result.on_bound == {"range_m": "lower"}
    assert result.E_soft == pytest.approx(math.sqrt(0.29), rel=1e-12)
    assert result.E_hard == pytest.approx(math.sqrt(0.29), rel=1e-12)
    slope = 0.04 / (2.0 * math.sqrt(0.29))
    assert result.gradient == pytest.approx({"range_m": slope}, rel=1e-9)
    assert result.gradient_E == pytest.approx({"range_m": slope}, rel=1e-9)
    assert result.names == ("range_m",) and result.cost_weight == 0.0 and result.cost == 0.0
    assert result.bounds == {"range_m": (10.0, 20.0)}


def test_a_repeated_solve_on_the_same_functions_costs_nothing():
    fns = _flat_bowl()
    first = box_solve(fns, BOUNDS)
    again = box_solve(fns, BOUNDS)
    assert first.counts["soft"] > 0 and first.counts["hard"] > 0
    assert again.counts == {"soft": 0, "hard": 0} and again.history == ()
    assert again.x_star == first.x_star and again.J_star == first.J_star


@pytest.mark.parametrize("start, on_bound", [(-5.0, 0.0), (25.0, 20.0)])
def test_a_start_outside_the_box_begins_on_its_bound(start, on_bound):
    result = box_solve(_flat_bowl(), BOUNDS, BoxConfig(starts=0), extra_starts=[[start]])
    assert result.history[0].kind == "hard" and result.history[0].x == (on_bound,)


def test_pareto_front_by_hand():
    points = [(1.0, 2.0), (1.0, 1.0), (2.0, 1.0), (0.5, 3.0), (0.5, 3.0)]
    # (1, 2) is beaten on cost at equal E, (2, 1) on E at equal cost; equal points keep each other.
    assert _pareto_front(points) == (False, True, False, True, True)


@pytest.mark.parametrize("seed", [0, 1])
def test_the_seed_shifts_the_hard_sample(seed):
    result = box_solve(_flat_bowl(), BOUNDS, BoxConfig(starts=0, seed=seed))
    sample = [e.x[0] for e in result.history if e.kind == "hard"]
    assert sample == (20.0 * halton(4, 1, seed)[:, 0]).tolist()
