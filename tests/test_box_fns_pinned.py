"""The box solve's evaluations (`diffsense/solve/_box_fns.py`) on functions worked by hand:
what is counted and recorded, the zero cost without a cost model, the gradient of E below 1 m,
and gradients of one parameter given as scalars (survivors of a partial solve run,
docs/mutation.md)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from diffsense.solve import Evaluator
from diffsense.solve._box_fns import BoxFunctions, Event
from tests.test_evaluator_pinned import Bowl


def _fns(cost=None):
    # E_soft^2(x, tau) = x^2 / 4 + tau / 100 [m^2], gradient x / 2 as a scalar (one parameter);
    # E_hard(x) = |x| / 2 [m].
    return BoxFunctions(("range_m",), lambda x, tau: (x[0] ** 2 / 4.0 + tau / 100.0, x[0] / 2.0),
                        lambda x: abs(x[0]) / 2.0, cost)


def test_each_new_soft_point_is_counted_and_recorded_once():
    fns, seen = _fns(), []
    fns.listener = seen.append
    for x, tau in ((1.0, 1.0), (2.0, 1.0), (1.0, 1.0), (1.0, 2.0)):
        fns.e2_soft([x], tau)
    assert fns.counts == {"soft": 3, "hard": 0}
    assert seen == fns.history == [Event("soft", (1.0,), 1.0, math.sqrt(0.26)),
                                   Event("soft", (2.0,), 1.0, math.sqrt(1.01)),
                                   Event("soft", (1.0,), 2.0, math.sqrt(0.27))]


def test_without_a_cost_model_j_is_e():
    fns = _fns()
    assert fns.cost([3.0])[0] == 0.0
    assert fns.j_hard([3.0], 5.0) == (1.5, 1.5, 0.0)  # E_hard(3) = 1.5 m


def test_gradients_of_one_parameter_come_back_as_vectors():
    fns = _fns(cost=lambda x: (2.0 * x[0], 2.0))
    assert fns.e2_soft([3.0], 1.0)[1].shape == (1,)
    assert fns.cost([3.0])[1].shape == (1,)


def test_the_gradient_of_e_below_one_metre():
    # At x = 1, tau = 1: E_soft = sqrt(0.26) = 0.51 m, dE^2/dx = 0.5, dE/dx = 0.5 / (2 E).
    j, grad, e = _fns().j_soft([1.0], 1.0, 0.0)
    assert e == pytest.approx(math.sqrt(0.26), rel=1e-15) and j == e
    np.testing.assert_allclose(grad, [0.5 / (2.0 * math.sqrt(0.26))], rtol=1e-15)


def test_from_an_evaluator_without_a_cost():
    # The bowl: E_soft^2(4, 1) = (4 - 3)^2 + 1/4 = 1.25 m^2 with gradient 2; E_hard(3) = 0.5 m.
    fns = BoxFunctions.from_evaluator(Evaluator(Bowl()))
    v, g = fns.e2_soft([4.0], 1.0)
    assert v == 1.25 and g.tolist() == [2.0]
    assert fns.j_hard([3.0], 5.0) == (0.5, 0.5, 0.0)
