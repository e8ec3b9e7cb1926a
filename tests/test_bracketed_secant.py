"""`BracketedSecant`, the root finder of dE^2/dr that stays in its bracket and finds minima only,
step by step against a plain-Python implementation of its stated rules, as branches on floats.
Each case records every point the solver asks g at and compares the whole sequence, the answer
and the stopping state (bound, evaluations) with the reference. The cases walk every branch:
probing right and left, the secant probe (overshoot, the 2-tol floor and the 4x-probe cap), the
doubling probe, Illinois regula falsi on a convex g that would stall plain regula falsi, the
narrow-bracket midpoint, both bounds, an exact zero, a NaN, and the float-resolution floor.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

from diffsense.solve import BracketedSecant

EPS64 = float(np.finfo(np.float64).eps)


def _reference(g, y0, lower, upper, xtol, probe=None, max_steps=40):
    """(points asked, answer, bound, evaluations) by the documented rules."""
    g = _on_floats(g)
    tol = max(xtol, 4.0 * EPS64 * max(abs(lower), abs(upper)))
    step = max(0.25 * (upper - lower) if probe is None else probe, 2.0 * xtol)
    lo, hi, g_lo, g_hi = lower, upper, None, None
    last_moved = None  # "lo" or "hi": which end the last evaluation replaced
    prev = None  # (y, g) of the evaluation before this one
    y, asked = y0, []
    for _ in range(max_steps):
        gy = g(y)
        asked.append(y)
        if not math.isfinite(gy):
            return asked, y, 0, len(asked)
        if gy < 0:
            if last_moved == "lo" and g_hi is not None:
                g_hi = g_hi / 2.0  # Illinois: the end kept twice in a row
            lo, g_lo, last_moved = y, gy, "lo"
        elif gy > 0:
            if last_moved == "hi" and g_lo is not None:
                g_lo = g_lo / 2.0
            hi, g_hi, last_moved = y, gy, "hi"
        else:
            last_moved = None
        if y <= lower and gy >= 0:
            return asked, lower, -1, len(asked)
        if y >= upper and gy <= 0:
            return asked, upper, 1, len(asked)
        if gy == 0:
            return asked, y, 0, len(asked)
        if g_lo is not None and g_hi is not None:
            if hi - lo <= 2.0 * tol:
                return asked, 0.5 * (lo + hi), 0, len(asked)
            y_next = min(max(lo - g_lo * ((hi - lo) / (g_hi - g_lo)), lo + tol), hi - tol)
        else:
            dist = step
            if prev is not None and y != prev[0]:
                slope = (gy - prev[1]) / (y - prev[0])
                if slope > 0:
                    dist = min(max(1.5 * abs(gy / slope), 2.0 * tol), 4.0 * step)
            y_next = min(max(y + (1.0 if gy < 0 else -1.0) * dist, lo), hi)
            step = 2.0 * step
        prev = (y, gy)
        y = y_next
    raise AssertionError("the reference did not stop")


def _on_floats(g):
    """g compiled as the solver compiles it, called on and returning Python floats."""
    jax.config.update("jax_enable_x64", True)
    compiled = jax.jit(g)
    return lambda y: float(compiled(jnp.asarray(y, jnp.float64)))


def _solver_points(g, y0, lower, upper, xtol, probe=None, **options):
    """(points asked, answer, bound, evaluations) of the solver itself."""
    jax.config.update("jax_enable_x64", True)
    asked = []

    def fn(y, args):
        jax.debug.callback(lambda v: asked.append(float(v)), y, ordered=True)
        return g(y)

    options = dict(lower=lower, upper=upper, **options)
    if probe is not None:
        options["probe"] = probe
    sol = optx.root_find(fn, BracketedSecant(rtol=0.0, atol=xtol), jnp.asarray(y0, jnp.float64),
                         options=options, max_steps=400, throw=False)
    jax.effects_barrier()
    return asked, float(sol.value), int(sol.state.bound), int(sol.stats["num_steps"])


def _kinked(y):
    """Slope 1e-3 below 1e8 + 0.3 and 5e-3 above: a root no secant step lands on exactly."""
    d = y - (1e8 + 0.3)
    return jnp.where(d < 0, 1e-3 * d, 5e-3 * d)


CASES = {
    # name: (g of a jax scalar, y0, lower, upper, xtol, probe)
    "convex_illinois": (lambda y: y**3 - 1.0, 0.1, 0.0, 4.0, 1e-10, None),
    "concave_from_the_right": (lambda y: 2.0 - 4.0 / (y + 0.5), 3.9, 0.0, 4.0, 1e-10, None),
    "probe_right_then_doubling": (lambda y: (y - 9.0) ** 3 + 0.25 * (y - 9.0), 0.2, 0.0, 10.0, 1e-9, 0.5),
    "probe_left": (lambda y: (y + 1.0) * (y + 1.0) * 0.1 + (y + 1.0), 7.0, -3.0, 8.0, 1e-9, 0.75),
    "flat_secant_capped": (lambda y: 1e-6 * (y - 50.0), 1.0, 0.0, 60.0, 1e-9, 0.5),
    "secant_floor": (lambda y: 4.0 * (y - 0.25) - 1e-7, 0.0, 0.0, 1.0, 1e-6, 0.25),
    "lower_bound": (lambda y: y + 1.0, 2.0, 0.0, 5.0, 1e-9, None),
    "upper_bound": (lambda y: y - 9.0, 1.0, 0.0, 5.0, 1e-9, None),
    "exact_zero": (lambda y: y - 2.0, 0.5, 0.0, 8.0, 1e-9, None),
    "nan": (lambda y: y * jnp.nan, 1.0, 0.0, 5.0, 1e-9, None),
    "coarse_tolerance_midpoint": (lambda y: y**3 - 1.0, 0.1, 0.0, 4.0, 0.05, None),
    "tiny_probe_floor": (lambda y: y - 0.5, 0.0, -1.0, 1.0, 1e-3, 1e-9),
    "wrong_way_slope": (lambda y: jnp.where(y < 2.0, -1.0 - y, y - 5.0), 0.5, 0.0, 8.0, 1e-9, None),
    "start_below_lower": (lambda y: y + 1.0, -1.5, 0.0, 5.0, 1e-9, None),
    "start_above_upper": (lambda y: y - 9.0, 6.5, 0.0, 5.0, 1e-9, None),
    "zero_at_lower": (lambda y: y, 0.0, 0.0, 5.0, 1e-9, None),
    "zero_at_upper": (lambda y: y - 5.0, 5.0, 0.0, 5.0, 1e-9, None),
    # Bracket [0, 1] after two evaluations, exactly 2 * xtol wide: stop at its midpoint.
    "exactly_two_tol_wide": (lambda y: y - 0.3, 0.0, 0.0, 1.0, 0.5, None),
    "resolution_floor": (_kinked, 1e8 + 0.0625, 1e8 - 1.0, 1e8 + 1.0, 1e-12, None),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_bracketed_secant_follows_its_rules(name):
    g, y0, lower, upper, xtol, probe = CASES[name]
    ref_asked, ref_y, ref_bound, ref_evals = _reference(g, y0, lower, upper, xtol, probe)
    asked, y, bound, evals = _solver_points(g, y0, lower, upper, xtol, probe)
    assert len(asked) == len(ref_asked) == evals == ref_evals, (asked, ref_asked)
    np.testing.assert_allclose(asked, ref_asked, rtol=1e-13, atol=0.0)
    assert y == pytest.approx(ref_y, rel=1e-13, abs=0.0)
    assert bound == ref_bound


def test_illinois_converges_where_plain_regula_falsi_crawls():
    """Plain regula falsi on y^3 - 1 over [0, 4] keeps the upper end fixed: from [0.1, 4] it needs
    about 150 evaluations to close the bracket to 2e-10; with the Illinois rule 10."""
    asked, y, _, _ = _solver_points(CASES["convex_illinois"][0], 0.1, 0.0, 4.0, 1e-10)
    assert y == pytest.approx(1.0, abs=1e-10) and len(asked) <= 14


def test_the_first_probe_is_a_quarter_of_the_bracket():
    # g(y) = y - 6 on [0, 8] from 0.5: g(0.5) = -5.5, probe 0.5 + 8/4 = 2.5 (g -3.5, secant slope
    # 1), overshoot 1.5 x 3.5 past it: 7.75 (g +1.75), then regula falsi 2.5 + 3.5 x 5.25 / 5.25 =
    # 6.0, an exact zero. Moved by +2 (y - 8 on [2, 10] from 2.5): the same steps, moved.
    assert _solver_points(lambda y: y - 6.0, 0.5, 0.0, 8.0, 1e-6)[:2] == ([0.5, 2.5, 7.75, 6.0], 6.0)
    assert _solver_points(lambda y: y - 8.0, 2.5, 2.0, 10.0, 1e-6)[:2] == ([2.5, 4.5, 9.75, 8.0], 8.0)


def test_max_evaluations_stops_it():
    asked, _, _, steps = _solver_points(lambda y: y - 6.0, 0.5, 0.0, 8.0, 1e-6, max_evaluations=2)
    assert asked == [0.5, 2.5] and steps == 2


def test_it_stops_at_the_float_resolution_of_its_bracket():
    # g jumps from -1 to +1 at c with no zero, on a bracket near 1e6 where neighbouring floats are
    # 1.2e-10 apart. Asked for xtol 0, it can only stop when the bracket is within 4 eps |r|
    # (8.9e-10) of closing; the halving Illinois steps get there in tens of steps, far short of
    # the 300 evaluations allowed.
    c = 1e6 + 3.3
    _, y, _, steps = _solver_points(lambda y: jnp.where(y < c, -1.0 - (c - y), 1.0 + (y - c)), 1e6 + 0.5,
                                        1e6, 1e6 + 10.0, 0.0, max_evaluations=300)
    assert steps < 100 and abs(y - c) <= 4.0 * EPS64 * (1e6 + 10.0)


def test_under_jit_it_finds_a_minimum_not_the_maximum_beside_its_start():
    # g = r^3 - r has roots at 0 (a maximum of E: g goes + to -) and at +-1 (minima).
    @jax.jit
    def find(r0):
        sol = optx.root_find(lambda r, _: r**3 - r, BracketedSecant(rtol=0.0, atol=1e-9), r0,
                             options=dict(lower=-0.5, upper=2.0), throw=False)
        return sol.value, sol.stats["num_steps"], sol.state.bound

    r, steps, bound = find(jnp.asarray(0.01))
    assert float(r) == pytest.approx(1.0, abs=1e-8) and int(bound) == 0 and int(steps) <= 20
