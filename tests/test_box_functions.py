"""What a box solve evaluates (`BoxFunctions`), on functions worked by hand: each distinct point
counted and recorded once, E = sqrt(E^2) recorded, J = E + weight * cost with dE/dx below 1 m,
one parameter's gradients as vectors; and the cost-weight sweep (`pareto_sweep`): one solve per
weight, warm-started from the previous answer, and which answers are Pareto-optimal."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.solve import BoxConfig, BoxFunctions, pareto_front, pareto_sweep


def _fns(cost=None):
    # E_soft^2(x, tau) = x^2 / 4 + tau / 100 [m^2], gradient x / 2 as a scalar (one parameter);
    # E_hard(x) = |x| / 2 [m].
    return BoxFunctions(("range_m",), lambda x, tau: (x[0] ** 2 / 4.0 + tau / 100.0, x[0] / 2.0),
                        lambda x: abs(x[0]) / 2.0, cost)


def test_each_new_point_is_counted_and_recorded_once_with_e_not_e2():
    fns, seen = _fns(), []
    fns.listener = seen.append
    for x, tau in ((1.0, 1.0), (2.0, 1.0), (1.0, 1.0), (1.0, 2.0)):
        fns.e2_soft([x], tau)
    fns.e_hard([3.0]), fns.e_hard([3.0])
    assert fns.counts == {"soft": 3, "hard": 1}
    assert seen == fns.history
    assert [(e.kind, e.x, e.tau, e.value) for e in fns.history] == [
        ("soft", (1.0,), 1.0, math.sqrt(0.26)), ("soft", (2.0,), 1.0, math.sqrt(1.01)),
        ("soft", (1.0,), 2.0, math.sqrt(0.27)), ("hard", (3.0,), None, 1.5)]
    assert fns.cost([3.0])[0] == 0.0 and fns.j_hard([3.0], 5.0) == (1.5, 1.5, 0.0)  # no cost model: J = E


def test_a_rounding_negative_e2_is_recorded_as_zero():
    values = {2.0: 2.25, 3.0: -1e-18}
    fns = BoxFunctions(("range_m",), lambda x, tau: (values[float(x[0])], np.zeros(1)), lambda x: 0.0)
    fns.e2_soft([2.0], 1.0), fns.e2_soft([3.0], 0.5)
    assert [e.value for e in fns.history] == [1.5, 0.0]


def test_the_gradient_of_e_below_one_metre_and_of_j_come_back_as_vectors():
    # At x = 1, tau = 1: E_soft = sqrt(0.26) = 0.51 m, dE^2/dx = 0.5, dE/dx = 0.5 / (2 E).
    j, grad, e = _fns().j_soft([1.0], 1.0, 0.0)
    assert e == pytest.approx(math.sqrt(0.26), rel=1e-15) and j == e
    np.testing.assert_allclose(grad, [0.5 / (2.0 * math.sqrt(0.26))], rtol=1e-15)
    # with a cost 2 x (its gradient a scalar, as E^2's) at weight 0.5: J = E + 1, dJ/dx = dE/dx + 1
    fns = _fns(cost=lambda x: (2.0 * x[0], 2.0))
    j, grad, _ = fns.j_soft([1.0], 1.0, 0.5)
    assert j == pytest.approx(math.sqrt(0.26) + 1.0, rel=1e-15)
    np.testing.assert_allclose(grad, [0.5 / (2.0 * math.sqrt(0.26)) + 1.0], rtol=1e-15)
    assert fns.e2_soft([3.0], 1.0)[1].shape == fns.cost([3.0])[1].shape == (1,)  # vectors


def test_the_sweep_over_weights_warm_starts_each_solve_from_the_previous_answer():
    # J = sqrt(1 + z^2) + lambda * cost, z = (x - 8) / 10, cost = x over [0, 10]: the minimum moves
    # down from 8 as lambda grows, to the lower bound by lambda = 0.2; the costs fall.
    fns = BoxFunctions.from_jax(("x",), lambda x, tau: 1.0 + ((x[0] - 8.0) / 10.0) ** 2,
                                lambda x: jnp.sqrt(1.0 + ((x[0] - 8.0) / 10.0) ** 2), cost=lambda x: x[0])
    asked, j_hard = [], fns.j_hard
    fns.j_hard = lambda x, weight: (asked.append((weight, float(x[0]))), j_hard(x, weight))[1]
    solved = []
    weights = [0.0, 0.02, 0.06, 0.2]
    results, front = pareto_sweep(fns, {"x": (0.0, 10.0)}, weights, BoxConfig(ftol=0.0), extra_starts=[[9.0]],
                                  on_solved=lambda k, w, r: solved.append((k, w, r)))
    assert [(k, w) for k, w, _ in solved] == list(enumerate(weights)) and [r for *_, r in solved] == list(results)
    # each weight's sample begins with the previous weight's answer, then the extra start
    firsts = [[x for w, x in asked if w == weight][:2] for weight in weights]
    assert firsts[0] == [9.0, firsts[0][1]] and firsts[0][1] != 9.0
    for k in (1, 2, 3):
        assert firsts[k] == [results[k - 1].x_star["x"], 9.0]
    costs = [r.cost for r in results]
    assert costs == sorted(costs, reverse=True) and all(front)
    assert results[0].x_star["x"] == pytest.approx(8.0, abs=1e-4) and results[-1].on_bound["x"] == "lower"
    assert [r.cost_weight for r in results] == weights


def test_the_pareto_front_by_hand():
    points = [(1.0, 2.0), (1.0, 1.0), (2.0, 1.0), (0.5, 3.0), (0.5, 3.0)]
    # (1, 2) is beaten on cost at equal E, (2, 1) on E at equal cost; equal points keep each other.
    assert pareto_front(points) == (False, True, False, True, True)
