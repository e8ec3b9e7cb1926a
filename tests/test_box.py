"""The box solve (`diffsense.solve._box`): known minima inside, on a bound and in a corner; no
point outside the box at any temperature or step; flags per parameter; the cost weight; the
answer chosen on the hard objective; and the composition Suite -> Objective -> Evaluator."""

from __future__ import annotations

import dataclasses
import math

import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.runtime._errors import InputError
from diffsense.solve._box import BoxConfig, box_solve
from diffsense.solve._pareto import pareto_sweep
from diffsense.solve._box_space import halton
from diffsense.solve._box_fns import BoxFunctions

NAMES = ("a_deg", "b_m", "c_px")
BOUNDS = {"a_deg": (30.0, 180.0), "b_m": (10.0, 200.0), "c_px": (640.0, 3840.0)}
LO, HI = np.array([30.0, 10.0, 640.0]), np.array([180.0, 200.0, 3840.0])
# An ill-conditioned, rotated bowl in units of each box: E^2 = 1 + z^T A z, z = (x - c) / width.
A = jnp.array([[4.0, 1.5, 0.0], [1.5, 1.0, 0.3], [0.0, 0.3, 0.5]])
# Converged to the last digits: the default ftol stops once J falls by < 0.01 % over 3 steps,
# which places a bowl's minimum only to ~1 % of the box.
EXACT = BoxConfig(ftol=0.0)


def bowl(center, ripple: float = 0.0):
    """E^2 as above; the soft version adds a ripple whose amplitude grows with tau (so each
    temperature has its own landscape); hard = the bowl itself."""
    c, w = jnp.asarray(center), jnp.asarray(HI - LO)

    def e2(x, tau):
        z = (x - c) / w
        return 1.0 + z @ A @ z + ripple * tau * jnp.sum(jnp.sin(40.0 * z) ** 2)

    return BoxFunctions.from_jax(NAMES, e2, lambda x: jnp.sqrt(e2(x, 0.0)))


def test_lands_on_an_interior_minimum():
    center = [100.0, 50.0, 2000.0]
    result = box_solve(bowl(center), BOUNDS, EXACT)
    for name, c, w in zip(NAMES, center, HI - LO):
        assert abs(result.x_star[name] - c) < 1e-4 * w, (name, result.x_star)
    assert result.on_bound == {n: "" for n in NAMES}
    assert result.E_hard == pytest.approx(1.0, abs=1e-8) and result.source.startswith("start")
    assert max(abs(g) for g in result.gradient.values()) < 1e-6
    assert result.counts["soft"] <= BoxConfig().max_soft + 2 * BoxConfig().starts + 1
    # E does not depend on tau here: each later level starts on the answer and stops at once.
    assert all(n <= 3 for start in result.starts for n in start.steps[1:]), result.starts


@pytest.mark.parametrize("center, flags", [
    ([200.0, 20.0, 2000.0], ("upper", "", "")),          # past the upper bound of a
    ([100.0, -40.0, 5000.0], ("", "lower", "upper")),    # past two bounds
    ([0.0, -100.0, 100.0], ("lower", "lower", "lower")),  # a corner
])
def test_minimum_on_a_bound_is_flagged_per_parameter(center, flags):
    result = box_solve(bowl(center), BOUNDS, EXACT)
    assert tuple(result.on_bound[n] for n in NAMES) == flags
    for name, flag, lo, hi in zip(NAMES, flags, LO, HI):
        x = result.x_star[name]
        if flag == "lower":
            assert x == lo and result.gradient[name] > 0  # J grows into the box
        elif flag == "upper":
            assert x == hi and result.gradient[name] < 0
    # The constrained minimum of the convex bowl, by projected gradient descent in numpy:
    ref = _projected_minimum(np.asarray(center))
    np.testing.assert_allclose([result.x_star[n] for n in NAMES], ref, atol=1e-4 * (HI - LO).max())


def _projected_minimum(center, steps=20000):
    w, a = HI - LO, np.asarray(A)
    z, zc = np.full(3, 0.5), (center - LO) / w
    lr = 1.0 / (2 * np.linalg.eigvalsh(a).max())
    for _ in range(steps):
        z = np.clip(z - lr * 2 * a @ (z - zc), 0.0, 1.0)
    return LO + w * z


def test_never_leaves_the_box_at_any_temperature_or_step():
    fns = bowl([0.0, 250.0, 3800.0], ripple=0.05)
    config = BoxConfig(starts=3, tau_schedule=(8.0, 2.0, 0.5, 0.1), max_steps=40, first_step_rad=3.0)
    result = box_solve(fns, BOUNDS, config)
    xs = np.array([e.x for e in result.history])
    assert len(xs) > 50 and {e.tau for e in result.history if e.kind == "soft"} == {8.0, 2.0, 0.5, 0.1}
    assert (xs >= LO).all() and (xs <= HI).all()


def test_answer_is_chosen_on_the_hard_objective():
    """The soft objective's minimum is at the centre; the hard one is 1 m worse within 5 % of it."""
    center = np.array([100.0, 50.0, 2000.0])

    def e2(x, tau):
        return 1.0 + jnp.sum(((x - center) / (HI - LO)) ** 2)

    def e_hard(x):
        near = jnp.max(jnp.abs(x - center) / (HI - LO)) < 0.05
        return jnp.sqrt(e2(x, 1.0)) + jnp.where(near, 1.0, 0.0)

    result = box_solve(BoxFunctions.from_jax(NAMES, e2, e_hard), BOUNDS)
    sample = [(e.value, e.x) for e in result.history if e.kind == "hard"]
    assert result.J_star == min(sample)[0] and result.source == "sample"
    assert tuple(result.x_star[n] for n in NAMES) == min(sample)[1]
    assert all(s.J_hard > result.J_star for s in result.starts)


def test_cost_weight_moves_the_minimum_as_computed_by_hand():
    """J = sqrt(1 + z^2) + lambda * cost with cost = 10 z: dJ/dz = 0 at z / sqrt(1 + z^2) = -10 lambda,
    so lambda = 0.06 puts z at -0.6 / 0.8 = -0.75 from the centre (in units of the box)."""
    names, bounds = ("x",), {"x": (0.0, 10.0)}
    fns = BoxFunctions.from_jax(names, lambda x, tau: 1.0 + ((x[0] - 8.0) / 10.0) ** 2,
                                lambda x: jnp.sqrt(1.0 + ((x[0] - 8.0) / 10.0) ** 2),
                                cost=lambda x: x[0])  # 10 z + 8 in the box's units
    result = box_solve(fns, bounds, dataclasses.replace(EXACT, cost_weight=0.06))
    assert result.x_star["x"] == pytest.approx(8.0 - 7.5, abs=1e-4)
    assert result.cost == pytest.approx(0.5, abs=1e-4)
    assert result.J_star == pytest.approx(math.sqrt(1 + 0.75**2) + 0.06 * 0.5, abs=1e-8)
    asked, j_hard = [], fns.j_hard
    fns.j_hard = lambda x, weight: (asked.append((weight, float(x[0]))), j_hard(x, weight))[1]
    solved = []
    results, front = pareto_sweep(fns, bounds, [0.0, 0.02, 0.06, 0.2], EXACT, extra_starts=[[9.0]],
                                  on_solved=lambda k, w, r: solved.append((k, w, r)))
    assert [(k, w) for k, w, _ in solved] == [(0, 0.0), (1, 0.02), (2, 0.06), (3, 0.2)]
    assert [r for _, _, r in solved] == list(results)
    # Warm start: each weight's sample begins with the previous weight's answer, then the extra start.
    firsts = [[x for w, x in asked if w == weight][:2] for weight in (0.0, 0.02, 0.06, 0.2)]
    assert firsts[0] == [9.0, firsts[0][1]] and firsts[0][1] != 9.0
    for k in (1, 2, 3):
        assert firsts[k] == [results[k - 1].x_star["x"], 9.0]
    costs = [r.cost for r in results]
    assert costs == sorted(costs, reverse=True) and all(front)
    assert results[0].x_star["x"] == pytest.approx(8.0, abs=1e-4) and results[-1].on_bound["x"] == "lower"


def test_halton_and_refusals():
    pts = halton(64, 3, seed=1)
    assert pts.shape == (64, 3) and (pts > 0).all() and (pts < 1).all()
    # Space-filling: every one of the 4 x 4 cells of each pair of axes holds 4 of the 64 points.
    for i, j in ((0, 1), (0, 2), (1, 2)):
        cells = np.histogram2d(pts[:, i], pts[:, j], bins=4, range=[[0, 1], [0, 1]])[0]
        assert cells.min() >= 2 and cells.max() <= 6
    fns = bowl([100.0, 50.0, 2000.0])
    with pytest.raises(InputError, match="lo < hi"):
        box_solve(fns, {"a_deg": (30.0, 30.0), "b_m": (1.0, 2.0), "c_px": (1.0, 2.0)})
    with pytest.raises(InputError, match="need \\(lo, hi\\) for each of 3"):
        box_solve(fns, [(0.0, 1.0)])
    with pytest.raises(InputError, match="largest first"):
        BoxConfig(tau_schedule=(1.0, 2.0))
