"""The bracketed secant (`diffsense/solve/_bracketed.py`) step by step against a plain-Python
implementation of the rules its module docstring states, written as branches on floats rather
than as masked array updates.

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

from diffsense.solve._bracketed import BracketedSecant

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


def _solver_points(g, y0, lower, upper, xtol, probe=None):
    jax.config.update("jax_enable_x64", True)
    asked = []

    def fn(y, args):
        jax.debug.callback(lambda v: asked.append(float(v)), y, ordered=True)
        return g(y)

    options = dict(lower=lower, upper=upper)
    if probe is not None:
        options["probe"] = probe
    sol = optx.root_find(fn, BracketedSecant(rtol=0.0, atol=xtol), jnp.asarray(y0, jnp.float64),
                         options=options, max_steps=40, throw=False)
    jax.effects_barrier()
    return asked, float(sol.value), int(sol.state.bound), int(sol.state.evaluations)


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


def test_illinois_beats_plain_regula_falsi_on_a_convex_derivative():
    """Plain regula falsi on g = y^3 - 1 over [0, 4] keeps the upper end fixed and converges
    linearly: from the bracket [0.1, 4] it needs about 150 evaluations to close it to 2e-10 (the
    same clipped steps without the halving, by hand); with the Illinois rule the solver needs 10."""
    asked, y, _, _ = _solver_points(CASES["convex_illinois"][0], 0.1, 0.0, 4.0, 1e-10)
    assert y == pytest.approx(1.0, abs=1e-10)
    assert len(asked) <= 14
