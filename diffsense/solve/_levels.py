"""The steps of the continuous solve (`_continuous.solve`): the counted objective, one
temperature level (the warm-started secant, or bisection after a downhill walk to a sign change),
and the hard polish around the answer."""

from __future__ import annotations

import math
from typing import Any

import equinox as eqx
import jax
import numpy as np

from diffsense.solve._bracketed import BracketedSecant
from diffsense.solve._solve_config import host_array


def e_from_e2(e2: Any) -> float:
    return math.sqrt(max(float(e2), 0.0))


class Counted:
    """Objective and gradient callables that count their evaluations (Python side).

    With `keep_values`, every gradient evaluation also keeps (r, E) of the soft value at r in
    `values_seen`: for a soft objective whose value is the answer objective's (straight-through
    under a probabilistic law) each is an answer candidate. A host `value_and_grad` gives the
    value with the gradient; otherwise it costs an uncounted soft evaluation.
    """

    def __init__(self, e2_soft, e_hard, dtype, value_and_grad=None, keep_values=False):
        self.dtype = dtype
        self._e2 = e2_soft
        self._e_hard = e_hard
        self._grad = jax.jit(jax.grad(e2_soft))
        if value_and_grad is not None:  # a host objective: compiled and memoised elsewhere
            self._e2 = lambda r, tau: value_and_grad(float(r), float(tau))[0]
            self._grad = lambda r, tau: value_and_grad(float(r), float(tau))[1]
        self.objective = 0
        self.gradient = 0
        self.keep_values = keep_values
        self.values_seen: list[tuple[float, float]] = []

    def as_r(self, r: float) -> np.ndarray:
        return host_array(r, self.dtype)

    def on_grid(self, r: float) -> float:
        """r rounded to the nearest number of the solve's dtype (float32 solves stay float32)."""
        return float(np.asarray(r, np.dtype(self.dtype)))

    def e2(self, r: float, tau: float) -> float:
        self.objective += 1
        return float(self._e2(self.as_r(r), self.as_r(tau)))

    def hard(self, r: float) -> float:
        self.objective += 1
        return float(self._e_hard(self.as_r(r)))

    def grad(self, r: float, tau: float) -> float:
        self.gradient += 1
        g = float(self._grad(self.as_r(r), self.as_r(tau)))
        if self.keep_values:
            self.values_seen.append((float(r), e_from_e2(self._e2(self.as_r(r), self.as_r(tau)))))
        return g


_SECANT = BracketedSecant(rtol=0.0, atol=0.0)


@eqx.filter_jit
def _secant_init(y, options):
    return _SECANT.init(None, y, None, options, jax.ShapeDtypeStruct((), y.dtype), None, frozenset())


@eqx.filter_jit
def _secant_step(g, y, options, state):
    # The solver's step evaluates g at y exactly once: hand it the value measured outside.
    y, state, _ = _SECANT.step(lambda y_, args: (g, None), y, None, options, state, frozenset())
    return y, state


def level_secant(counted, y0, tau, lower, upper, probe, tol, max_steps, budget):
    """One temperature level: optimistix's init/step/terminate loop of `BracketedSecant`, driven
    from Python so that each gradient comes from the objective's own compiled program (no host
    callback inside a compiled loop: every program stays in the persistent compilation cache).
    The options are traced values: the levels share two small compiled programs."""
    options = dict(
        lower=counted.as_r(lower),
        upper=counted.as_r(upper),
        probe=counted.as_r(probe),
        xtol=counted.as_r(tol),
    )  # the Python loop below ends a level at its share: no max_evaluations option to read
    y = counted.as_r(y0)
    state = _secant_init(y, options)
    n = 0
    while n < budget and not (bool(state.done) or n >= max_steps):
        g = counted.as_r(counted.grad(float(y), tau))
        y, state = _secant_step(g, y, options, state)
        n += 1
    if bool(state.nonfinite):
        raise FloatingPointError(f"dE^2/dr is not finite near r={float(y)} (tau={tau})")
    return float(y), n, int(state.bound), bool(state.done)


def hard_polish_walk(counted, r, e_hard, lower, upper, probes, min_step):
    """Compass search on E_hard from (r, e_hard) inside [lower, upper]: probe r + step, then
    r - step, move on a strict improvement, halve the step when neither side improves. Spends
    at most `probes` hard evaluations (probes outside the bracket cost nothing); returns the best
    (r, E_hard) seen."""
    step = (upper - lower) / 16.0
    while probes > 0 and step >= min_step:
        moved = False
        for candidate in (r + step, r - step):
            if probes == 0 or not lower <= candidate <= upper:
                continue
            probes -= 1
            e = counted.hard(candidate)
            if e < e_hard:
                r, e_hard, moved = candidate, e, True
                break
        if not moved:
            step *= 0.5
    return r, e_hard


def _checked_grad(counted, r, tau):
    value = counted.grad(r, tau)
    if not math.isfinite(value):
        raise FloatingPointError(f"dE^2/dr is not finite at r={r} (tau={tau})")
    return value


def _bracket_from(counted, y0, tau, lower, upper, step, evaluations):
    """Walk downhill from y0 with doubling steps (the first `step`) until dE^2/dr changes sign.

    Returns (a, b, bound): the minimum lies in [a, b] (g(a) < 0 < g(b)); a == b is the answer
    itself (an exact zero of g, or a bracket end with bound -1 / +1); None when the
    `evaluations` allowed ran out first (then a == b is the furthest point reached downhill).
    """
    y = counted.on_grid(min(max(y0, lower), upper))
    g_y = _checked_grad(counted, y, tau)
    if g_y == 0.0:
        return y, y, 0
    direction = -1.0 if g_y > 0 else 1.0
    end = lower if direction < 0 else upper
    for _ in range(evaluations - 1):
        if y == end:
            return y, y, int(direction)  # downhill all the way to the bracket's end
        probe = counted.on_grid(min(max(y + direction * step, lower), upper))
        while probe == y and step > 0:  # a step below the grid spacing rounds back to y: no new point
            step *= 2.0
            probe = counted.on_grid(min(max(y + direction * step, lower), upper))
        g_probe = _checked_grad(counted, probe, tau)
        if (g_probe > 0) != (g_y > 0) or g_probe == 0.0:
            return (y, probe, 0) if direction > 0 else (probe, y, 0)
        y, step = probe, 2.0 * step
    return (y, y, int(direction)) if y == end else (y, y, None)


def level_bisection(counted, y0, tau, lower, upper, tol, max_steps):
    """One continuation level by bisection, warm-started at y0 (the previous level's answer).

    dE^2/dr is evaluated at y0 and at points walking downhill from it with doubling steps
    (first: `tol`) until its sign changes; the bracket is then halved at its midpoint until it
    is narrower than `tol`, and its midpoint returned. A warm start near the answer costs about
    three gradient evaluations per level, where bisecting the whole bracket at every level
    spends the budget before the last one. At most `max_steps` gradient evaluations; every point
    lies on the solve's float grid; a gradient that is not finite is an error. Returns
    ((r, bound), evaluations, converged) with bound -1 / +1 when the minimum is on the
    bracket's lower / upper edge.
    """
    before = counted.gradient
    a, b, bound = _bracket_from(counted, y0, tau, lower, upper, tol, max_steps)
    if bound is None or a == b:
        return (a, bound or 0), counted.gradient - before, bound is not None
    width = b - a
    # halvings until the bracket is narrower than tol
    needed = math.floor(math.log2(width / tol)) + 1 if width >= tol else 0
    steps = min(needed, max_steps - (counted.gradient - before))
    for _ in range(max(steps, 0)):
        mid = counted.on_grid(0.5 * (a + b))
        if not a < mid < b:  # the grid has no point strictly inside: as narrow as it gets
            break
        g = counted.grad(mid, tau)
        if not math.isfinite(g):
            raise FloatingPointError(f"dE^2/dr is not finite in [{a}, {b}] (tau={tau})")
        if g == 0.0:
            return (mid, 0), counted.gradient - before, True
        a, b = (a, mid) if g > 0 else (mid, b)
    return (counted.on_grid(0.5 * (a + b)), 0), counted.gradient - before, steps == needed
