"""The box solve, argmin of J = E + cost_weight * cost over many parameters with bounds, on problems
worked by hand: a known minimum inside, on a bound or in a corner (flagged per parameter), no
point outside the box, the answer chosen on the hard objective, the gradient and E at the answer,
the cost weight's effect, the coarse Halton sample, the stopping rules and the refusals."""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.runtime import InputError
from diffsense.solve import BoxConfig, BoxFunctions, box_solve

NAMES = ("a_deg", "b_m", "c_px")
BOUNDS = {"a_deg": (30.0, 180.0), "b_m": (10.0, 200.0), "c_px": (640.0, 3840.0)}
LO, HI = np.array([30.0, 10.0, 640.0]), np.array([180.0, 200.0, 3840.0])
# An ill-conditioned, rotated bowl in units of each box: E^2 = 1 + z^T A z, z = (x - c) / width.
A = jnp.array([[4.0, 1.5, 0.0], [1.5, 1.0, 0.3], [0.0, 0.3, 0.5]])
# Converged to the last digits: the default ftol stops once J falls by < 0.01 % over 3 steps,
# which places a bowl's minimum only to ~1 % of the box.
EXACT = BoxConfig(ftol=0.0)
RANGE = {"range_m": (0.0, 20.0)}


@pytest.fixture(autouse=True)
def _x64():
    jax.config.update("jax_enable_x64", True)


def bowl(center, ripple: float = 0.0):
    """E^2 as above; the soft version adds a ripple whose amplitude grows with tau (so each
    temperature has its own landscape); hard = the bowl itself."""
    c, w = jnp.asarray(center), jnp.asarray(HI - LO)

    def e2(x, tau):
        z = (x - c) / w
        return 1.0 + z @ A @ z + ripple * tau * jnp.sum(jnp.sin(40.0 * z) ** 2)

    return BoxFunctions.from_jax(NAMES, e2, lambda x: jnp.sqrt(e2(x, 0.0)))


def one(e2, e_hard, cost=None):
    """One parameter, range_m: E_soft^2 = e2(x, tau), E_hard = e_hard(x) of a scalar x."""
    return BoxFunctions.from_jax(("range_m",), lambda x, tau: e2(x[0], tau), lambda x: e_hard(x[0]),
                                 cost=None if cost is None else lambda x: cost(x[0]))


def flat_bowl():
    """E_soft^2 = 1 + tau + (x - 8)^2 / 100, E_hard^2 = 1 + (x - 8)^2 / 100: the minimum at 8."""
    return one(lambda x, tau: 1.0 + tau + (x - 8.0) ** 2 / 100.0, lambda x: jnp.sqrt(1.0 + (x - 8.0) ** 2 / 100.0))


def _hard_sample(result):
    return [e.x for e in result.history if e.kind == "hard"]


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


def _projected_minimum(center, steps=20000):
    """The constrained minimum of the convex bowl, by projected gradient descent in numpy."""
    w, a = HI - LO, np.asarray(A)
    z, zc = np.full(3, 0.5), (center - LO) / w
    lr = 1.0 / (2 * np.linalg.eigvalsh(a).max())
    for _ in range(steps):
        z = np.clip(z - lr * 2 * a @ (z - zc), 0.0, 1.0)
    return LO + w * z


@pytest.mark.parametrize("center, flags", [
    ([200.0, 20.0, 2000.0], ("upper", "", "")),          # past the upper bound of a
    ([100.0, -40.0, 5000.0], ("", "lower", "upper")),    # past two bounds
    ([0.0, -100.0, 100.0], ("lower", "lower", "lower")),  # a corner
])
def test_a_minimum_on_a_bound_is_flagged_per_parameter(center, flags):
    result = box_solve(bowl(center), BOUNDS, EXACT)
    assert tuple(result.on_bound[n] for n in NAMES) == flags
    for name, flag, lo, hi in zip(NAMES, flags, LO, HI):
        if flag == "lower":
            assert result.x_star[name] == lo and result.gradient[name] > 0  # J grows into the box
        elif flag == "upper":
            assert result.x_star[name] == hi and result.gradient[name] < 0
    np.testing.assert_allclose([result.x_star[n] for n in NAMES], _projected_minimum(np.asarray(center)),
                               atol=1e-4 * (HI - LO).max())


def test_at_a_lower_bound_the_gradient_and_e_soft_are_the_last_temperatures():
    # E_soft^2 = 1/4 + tau (x - 8)^2 / 100 over [10, 20] ends at x = 10, where at tau 1
    # E_soft = sqrt(0.29) m and dE^2/dx = 0.04, so dE/dx = 0.04 / (2 sqrt(0.29)) (at tau 2 it would
    # be 0.08 / (2 sqrt(0.33))); no cost: the gradient of J is that of E.
    fns = one(lambda x, tau: 0.25 + tau * (x - 8.0) ** 2 / 100.0, lambda x: jnp.sqrt(0.25 + (x - 8.0) ** 2 / 100.0))
    result = box_solve(fns, {"range_m": (10.0, 20.0)}, BoxConfig(tau_schedule=(4.0, 2.0, 1.0)))
    assert result.x_star == {"range_m": 10.0} and result.on_bound == {"range_m": "lower"}
    assert result.E_soft == pytest.approx(math.sqrt(0.29), rel=1e-12)
    assert result.E_hard == pytest.approx(math.sqrt(0.29), rel=1e-12)
    slope = 0.04 / (2.0 * math.sqrt(0.29))
    assert result.gradient == pytest.approx({"range_m": slope}, rel=1e-9)
    assert result.gradient_E == pytest.approx({"range_m": slope}, rel=1e-9)
    assert result.names == ("range_m",) and result.cost_weight == 0.0 and result.cost == 0.0
    assert result.bounds == {"range_m": (10.0, 20.0)}


def test_a_bound_answer_where_e_and_j_part():
    # E identically 0 and J = E + 0.5 x over [1, 3]: the minimum is on x = 1, where dJ/dx = 0.5
    # and dE/dx = 0 (0, not NaN, at E = 0).
    fns = one(lambda x, tau: 0.0 * x, lambda x: 0.0 * x, cost=lambda x: x)
    result = box_solve(fns, {"range_m": (1.0, 3.0)}, BoxConfig(cost_weight=0.5, tau_schedule=(2.0, 1.0)))
    assert result.x_star == {"range_m": 1.0} and result.on_bound == {"range_m": "lower"}
    assert result.E_soft == 0.0 and result.E_hard == 0.0 and result.J_star == pytest.approx(0.5, abs=1e-12)
    assert result.gradient == pytest.approx({"range_m": 0.5}, abs=1e-12) and result.gradient_E == {"range_m": 0.0}


def test_a_minimum_within_bound_tol_is_put_on_the_bound():
    fns = one(lambda x, tau: 1.0 + (x - 0.1) ** 2, lambda x: jnp.sqrt(1.0 + (x - 0.1) ** 2))
    result = box_solve(fns, {"range_m": (0.0, 1.0)}, BoxConfig(bound_tol=0.25))
    assert result.x_star == {"range_m": 0.0} and result.on_bound == {"range_m": "lower"}


def test_never_leaves_the_box_at_any_temperature_or_step():
    fns = bowl([0.0, 250.0, 3800.0], ripple=0.05)
    config = BoxConfig(starts=3, tau_schedule=(8.0, 2.0, 0.5, 0.1), max_steps=40, first_step_rad=3.0)
    result = box_solve(fns, BOUNDS, config)
    xs = np.array([e.x for e in result.history])
    assert len(xs) > 50 and {e.tau for e in result.history if e.kind == "soft"} == {8.0, 2.0, 0.5, 0.1}
    assert (xs >= LO).all() and (xs <= HI).all()


@pytest.mark.parametrize("start, first", [(-10.0, -5.0), (1.0, 0.2)])
def test_a_start_outside_the_box_begins_on_its_bound(start, first):
    # On [-5, 0.2], -5 + 5.2 = 0.20000000000000018 > 0.2: the upper bound is 0.2 exactly all the same.
    fns = one(lambda x, tau: 1.0 + x**2, lambda x: jnp.sqrt(1.0 + x**2))
    result = box_solve(fns, {"range_m": (-5.0, 0.2)}, BoxConfig(starts=0), extra_starts=[[start]])
    assert result.history[0].kind == "hard" and result.history[0].x == (first,)


def test_the_answer_is_chosen_on_the_hard_objective():
    """The soft objective's minimum is at the centre; the hard one is 1 m worse within 5 % of it."""
    center = np.array([100.0, 50.0, 2000.0])

    def e2(x, tau):
        return 1.0 + jnp.sum(((x - center) / (HI - LO)) ** 2)

    def e_hard(x):
        return jnp.sqrt(e2(x, 1.0)) + jnp.where(jnp.max(jnp.abs(x - center) / (HI - LO)) < 0.05, 1.0, 0.0)

    # checked only where levels end (iterates checked on the way: tests/test_design_screen.py)
    result = box_solve(BoxFunctions.from_jax(NAMES, e2, e_hard), BOUNDS, BoxConfig(check_every=0))
    sample = [(e.value, e.x) for e in result.history if e.kind == "hard"]
    assert result.J_star == min(sample)[0] and result.source == "sample"
    assert tuple(result.x_star[n] for n in NAMES) == min(sample)[1]
    assert all(s.J_hard > result.J_star for s in result.starts)


def test_ties_on_the_hard_objective_go_to_the_first_candidate():
    # A soft bowl at 8 with E_hard 1 m within 0.2 of 8 and 2 m elsewhere (no sample point is that
    # close): every level of every start lands there; the first to reach 1 m is start 0 at tau 4.
    result = box_solve(one(lambda x, tau: 1.0 + (x - 8.0) ** 2, lambda x: jnp.where(jnp.abs(x - 8.0) < 0.2, 1.0, 2.0)),
                       RANGE, EXACT)
    assert min(e.value for e in result.history[:4]) == 2.0
    assert [s.J_hard for s in result.starts] == [1.0, 1.0]
    assert result.J_star == 1.0 and result.source.startswith("start 0 tau 4")  # its level's end, or on the way


def test_each_start_reports_j_soft_at_the_last_temperature():
    result = box_solve(flat_bowl(), RANGE, BoxConfig(tau_schedule=(4, 2.0, 1.0)))
    assert result.starts and result.tau_schedule == (4.0, 2.0, 1.0)
    for start in result.starts:
        x = start.x["range_m"]
        assert start.J_soft == pytest.approx(np.sqrt(2.0 + (x - 8.0) ** 2 / 100.0), rel=1e-12)


def test_the_cost_weight_moves_the_minimum_as_computed_by_hand():
    """J = sqrt(1 + z^2) + lambda * cost with cost = 10 z: dJ/dz = 0 at z / sqrt(1 + z^2) = -10
    lambda, so lambda = 0.06 puts z at -0.6 / 0.8 = -0.75 from the centre (in units of the box)."""
    fns = one(lambda x, tau: 1.0 + ((x - 8.0) / 10.0) ** 2, lambda x: jnp.sqrt(1.0 + ((x - 8.0) / 10.0) ** 2),
              cost=lambda x: x)
    result = box_solve(fns, {"range_m": (0.0, 10.0)}, dataclasses.replace(EXACT, cost_weight=0.06))
    assert result.x_star["range_m"] == pytest.approx(8.0 - 7.5, abs=1e-4)
    assert result.cost == pytest.approx(0.5, abs=1e-4)
    assert result.J_star == pytest.approx(math.sqrt(1 + 0.75**2) + 0.06 * 0.5, abs=1e-8)


def test_without_a_soft_budget_each_start_stays_on_its_sample_point():
    result = box_solve(flat_bowl(), RANGE, BoxConfig(max_soft=0, starts=2))
    sample = sorted((e.value, e.x[0]) for e in result.history if e.kind == "hard")
    assert len(sample) == 4  # 2 d + 2 points, each start's answers among them
    for k, start in enumerate(result.starts):
        assert start.steps == (0, 0, 0) and start.x0 == start.x == {"range_m": sample[k][1]}
    assert result.counts["soft"] == 2 and result.x_star == {"range_m": sample[0][1]}


def test_a_repeated_solve_on_the_same_functions_costs_nothing():
    fns = flat_bowl()
    first, again = box_solve(fns, RANGE), box_solve(fns, RANGE)
    assert first.counts["soft"] > 0 and first.counts["hard"] > 0
    assert again.counts == {"soft": 0, "hard": 0} and again.history == ()
    assert again.x_star == first.x_star and again.J_star == first.J_star


def _radical_inverse(i: int, base: int) -> float:
    x, f = 0.0, 1.0
    while i:
        f /= base
        x, i = x + f * (i % base), i // base
    return x


@pytest.mark.parametrize("seed", [0, 1])
def test_the_coarse_sample_is_a_halton_sequence_shifted_by_the_seeds_draw(seed):
    # 2 d + 2 = 6 points by default, or `samples`: the radical inverses in bases 2 and 3 of
    # 1, 2, ..., rotated modulo 1 by numpy's uniform draw from the seed (Cranley-Patterson).
    def solved(**config):
        fns = BoxFunctions.from_jax(["a", "b"], lambda x, tau: jnp.sum((x - 0.3) ** 2), lambda x: jnp.hypot(*(x - 0.3)))
        return _hard_sample(box_solve(fns, {"a": (0.0, 1.0), "b": (0.0, 10.0)}, BoxConfig(starts=0, seed=seed, **config)))

    radical = np.array([[_radical_inverse(i, 2), _radical_inverse(i, 3)] for i in range(1, 10)])
    expected = (radical + np.random.default_rng(seed).uniform(size=2)) % 1.0 * [1.0, 10.0]
    np.testing.assert_allclose(solved(), expected[:6], rtol=0, atol=1e-14)
    np.testing.assert_allclose(solved(samples=9), expected, rtol=0, atol=1e-14)


@pytest.mark.parametrize("shift, point", [(0.5, 1e-9), (0.5 - 1e-12, 1.0 - 1e-9)])
def test_a_sample_point_on_the_boxs_edge_is_moved_inside(monkeypatch, shift, point):
    # Base 2's first point 1/2 shifted by 1/2 is 0, by 1/2 - 1e-12 is 1 - 1e-12: moved 1e-9 inside,
    # where the sine transform still has a slope for BFGS to follow.
    monkeypatch.setattr(np.random, "default_rng", lambda seed: type("Shift", (), {
        "uniform": lambda self, size: np.full(size, shift)})())
    result = box_solve(flat_bowl(), {"range_m": (0.0, 1.0)}, BoxConfig(starts=0, samples=1))
    assert _hard_sample(result)[0] == (point,)


def test_a_run_stops_at_max_steps():
    # No tolerance can stop it (all 0: optimistix's test is strict), so only the step cap does.
    result = box_solve(flat_bowl(), RANGE, BoxConfig(starts=1, max_steps=2, ftol=0.0, rtol=0.0, atol=0.0))
    assert result.starts[0].steps == (2, 2, 2)


def test_the_runs_stop_at_the_soft_budget():
    # J(t0) for the scale, optimistix's first step at t0 again (the same point: no new
    # evaluation), then one new trial point a step: the budget of 4 ends the first level at 4
    # steps and leaves the later levels none.
    result = box_solve(flat_bowl(), RANGE, BoxConfig(starts=1, max_soft=4, ftol=0.0, rtol=0.0, atol=0.0))
    assert result.starts[0].steps == (4, 0, 0)
    assert 4 <= result.counts["soft"] <= 4 + 2  # the start's J_soft and the answer's gradient


def _stalled_level(schedule, ftol):
    # The bowl 1 + (x - 8)^4 / 1000 from x = 1 (seed 1's one sample point, 0.24, is worse): E does
    # not depend on tau and rtol = atol = 0, so only the stall test ends a level.
    fns = one(lambda x, tau: 1.0 + (x - 8.0) ** 4 / 1000.0, lambda x: jnp.sqrt(1.0 + (x - 8.0) ** 4 / 1000.0))
    config = BoxConfig(samples=1, seed=1, starts=1, tau_schedule=schedule, ftol=ftol, rtol=0.0, atol=0.0,
                       max_steps=60)
    result = box_solve(fns, RANGE, config, extra_starts=[[1.0]])
    assert result.starts[0].x0["range_m"] == pytest.approx(1.0, abs=1e-12)
    return result.starts[0].steps[0]


def test_the_stall_tolerance_is_scaled_by_tau_over_the_last_tau():
    # A level at tau 4 of (4, 1) with ftol 1e-4 takes the steps of a level at tau 1 of (1,) with
    # 4e-4: it stalls after 6 steps; a quarter of that tolerance stalls later.
    early = _stalled_level((4.0, 1.0), 1e-4)
    assert early == _stalled_level((1.0,), 4e-4) == 6
    assert _stalled_level((1.0,), 1e-4) > early


@pytest.mark.parametrize("kwargs, culprit", [
    (dict(cost_weight=-1.0), "cost_weight"), (dict(cost_weight=math.inf), "cost_weight"),
    (dict(cost_weight=math.nan), "cost_weight"),
    (dict(tau_schedule=(1.0, -1.0)), "tau_schedule"), (dict(tau_schedule=(math.inf, 1.0)), "tau_schedule"),
    (dict(tau_schedule=(2.0, 0.0)), "tau_schedule"), (dict(tau_schedule=(1.0, 2.0)), "tau_schedule"),
    (dict(tau_schedule=()), "tau_schedule"),
    (dict(samples=-1), "samples"), (dict(starts=-1), "starts"), (dict(max_steps=-1), "max_steps"),
    (dict(max_soft=-1), "max_soft"),
])
def test_a_bad_box_config_is_one_input_error(kwargs, culprit):
    with pytest.raises(InputError, match=culprit):
        BoxConfig(**kwargs)


def test_bad_bounds_are_refused_naming_the_parameter():
    fns = bowl([100.0, 50.0, 2000.0])
    with pytest.raises(InputError, match="a_deg"):
        box_solve(fns, {"a_deg": (30.0, 30.0), "b_m": (1.0, 2.0), "c_px": (1.0, 2.0)})
    with pytest.raises(InputError, match="b_m"):
        box_solve(fns, {"a_deg": (30.0, 40.0), "b_m": (1.0, math.inf), "c_px": (1.0, 2.0)})
    with pytest.raises(InputError, match="each of 3"):
        box_solve(fns, [(0.0, 1.0)])


def test_the_box_solve_turns_float64_on():
    jax.config.update("jax_enable_x64", False)
    try:
        result = box_solve(flat_bowl(), RANGE)
        assert jax.config.jax_enable_x64
        assert result.x_star["range_m"] == pytest.approx(8.0, abs=1e-3)
    finally:
        jax.config.update("jax_enable_x64", True)
