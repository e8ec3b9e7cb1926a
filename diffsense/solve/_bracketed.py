"""A 1-D optimistix root finder for dE/dr that stays inside a bracket and finds minima only.

`BracketedSecant` looks for a point where the derivative g = dE/dr changes sign from - to +
(a local minimum of E) inside `[lower, upper]`, or decides that the minimum is on a bound
(g(lower) >= 0 or g(upper) <= 0). It never leaves the bracket and never converges to a maximum,
which plain Newton on g can.

Each step evaluates g exactly once, at one call site in the traced program (so the objective's
gradient is compiled once), and `stats["num_steps"]` is the number of gradient evaluations.
- While only one side of the minimum is known, it probes towards the other side: the secant
  extrapolation of the last two points, overshot by half, or a doubling probe step.
- Once g(lo) < 0 < g(hi) is known, it takes Illinois regula-falsi steps (superlinear, always
  bracketed), kept `atol` away from both ends so the bracket shrinks by at least `atol` a step.
It stops when the bracket is at most 2 * atol wide (the answer, its midpoint, is then within
atol of a sign change), at an exact zero of g, on a bound, or on a non-finite g.

Options: `lower`, `upper` (the bracket, required), `probe` (first probe step, default a
quarter of the bracket), `xtol` (overrides `atol`) and `max_evaluations` (stop after this many
steps). Options are traced values: changing them between solves does not recompile, while
changing the solver's fields or `max_steps` does.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

import equinox as eqx
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, Bool, Int, PyTree, Scalar

# Overshoot of a secant extrapolation while probing: lands past the estimated root, so the
# next evaluation usually closes the bracket.
_OVERSHOOT = 1.5
# A secant probe is capped at this many times the current probe step (guards a flat secant).
_MAX_PROBE_GROWTH = 4.0


class _State(eqx.Module):
    lo: Scalar  # the minimum lies in [lo, hi]
    hi: Scalar
    g_lo: Scalar  # g at lo (< 0); NaN while lo has not been evaluated
    g_hi: Scalar  # g at hi (> 0); NaN while hi has not been evaluated
    y_prev: Scalar  # the point evaluated before the last one (secant extrapolation)
    g_prev: Scalar
    side: Int[Array, ""]  # which end moved last: -1 lo, +1 hi, 0 none (Illinois rule)
    probe: Scalar  # current probe step while one side is unknown
    evaluations: Int[Array, ""]  # g evaluations so far
    bound: Int[Array, ""]  # -1 minimum on lower, +1 on upper, 0 interior
    done: Bool[Array, ""]
    nonfinite: Bool[Array, ""]


def _safe_div(num: Array, den: Array) -> Array:
    ok = den != 0
    return jnp.where(ok, num / jnp.where(ok, den, 1.0), jnp.inf)


class BracketedSecant(optx.AbstractRootFinder):
    """Minimum of E on a bracket from g = dE/dr: safeguarded secant (regula falsi) root finding.

    Attributes:
        rtol: unused (optimistix requires the field); tolerances are absolute in r.
        atol: the tolerance on r: the answer is within `atol` of a sign change of g.
    """

    rtol: float
    atol: float
    norm: ClassVar[Callable[[PyTree], Scalar]] = jnp.abs

    def _xtol(self, options: dict, dtype) -> Array:
        return jnp.asarray(options.get("xtol", self.atol), dtype)

    def init(self, fn, y, args, options, f_struct, aux_struct, tags) -> _State:
        del fn, args, aux_struct, tags
        dtype = f_struct.dtype
        lower = jnp.asarray(options["lower"], dtype)
        upper = jnp.asarray(options["upper"], dtype)
        probe = jnp.asarray(options.get("probe", 0.25 * (upper - lower)), dtype)
        nan = jnp.array(jnp.nan, dtype)
        return _State(
            lo=lower,
            hi=upper,
            g_lo=nan,
            g_hi=nan,
            y_prev=nan,
            g_prev=nan,
            side=jnp.array(0),
            probe=jnp.maximum(probe, 2.0 * self._xtol(options, dtype)),
            evaluations=jnp.array(0),
            bound=jnp.array(0),
            done=jnp.array(False),
            nonfinite=jnp.array(False),
        )

    def step(self, fn, y, args, options, state: _State, tags):
        del tags
        lower = jnp.asarray(options["lower"], y.dtype)
        upper = jnp.asarray(options["upper"], y.dtype)
        # A tolerance below the float resolution at the bracket could never be met.
        resolution = 4.0 * jnp.finfo(y.dtype).eps * jnp.maximum(jnp.abs(lower), jnp.abs(upper))
        tol = jnp.maximum(self._xtol(options, y.dtype), resolution)
        g, aux = fn(y, args)
        finite = jnp.isfinite(g)
        neg, pos = g < 0, g > 0

        lo = jnp.where(neg, y, state.lo)
        hi = jnp.where(pos, y, state.hi)
        g_lo = jnp.where(neg, g, state.g_lo)
        g_hi = jnp.where(pos, g, state.g_hi)
        # Illinois: an end kept twice in a row has its value halved, so regula falsi cannot
        # stall with one end fixed (order ~1.44 instead of linear convergence).
        g_hi = jnp.where(neg & (state.side == -1), 0.5 * g_hi, g_hi)
        g_lo = jnp.where(pos & (state.side == 1), 0.5 * g_lo, g_lo)
        side = jnp.where(neg, -1, jnp.where(pos, 1, 0))

        bound = jnp.where((y <= lower) & ~neg, -1, jnp.where((y >= upper) & ~pos, 1, 0))
        bracketed = jnp.isfinite(g_lo) & jnp.isfinite(g_hi)
        narrow = bracketed & (hi - lo <= 2.0 * tol)
        done = (g == 0) | (bound != 0) | narrow | ~finite

        # Inside a known bracket: regula falsi, at least tol from both ends.
        y_rf = lo - g_lo * _safe_div(hi - lo, g_hi - g_lo)
        y_inside = jnp.clip(y_rf, lo + tol, hi - tol)
        # One side known: probe towards the other (right while g < 0, left while g > 0).
        direction = jnp.where(neg, 1.0, -1.0).astype(y.dtype)
        slope = _safe_div(g - state.g_prev, y - state.y_prev)
        secant_dist = _OVERSHOOT * jnp.abs(_safe_div(g, slope))
        usable = jnp.isfinite(secant_dist) & (slope > 0)
        dist = jnp.where(
            usable, jnp.clip(secant_dist, 2.0 * tol, _MAX_PROBE_GROWTH * state.probe), state.probe
        )
        y_probe = jnp.clip(y + direction * dist, lo, hi)
        probe = jnp.where(bracketed, state.probe, 2.0 * state.probe)

        y_next = jnp.where(bracketed, y_inside, y_probe)
        y_done = jnp.where(
            bound == -1, lower, jnp.where(bound == 1, upper, jnp.where(narrow, 0.5 * (lo + hi), y))
        )
        new_y = jnp.where(done, y_done, y_next)
        new_state = _State(
            lo=lo,
            hi=hi,
            g_lo=g_lo,
            g_hi=g_hi,
            y_prev=y,
            g_prev=g,
            side=side,
            probe=probe,
            evaluations=state.evaluations + 1,
            bound=jnp.where(finite, bound, 0),
            done=done,
            nonfinite=~finite,
        )
        return new_y, new_state, aux

    def terminate(self, fn, y, args, options, state: _State, tags):
        del fn, y, args, tags
        spent = state.evaluations >= options.get("max_evaluations", jnp.iinfo(jnp.int32).max)
        return state.done | spent, optx.RESULTS.successful

    def postprocess(self, fn, y, aux, args, options, state, tags, result) -> tuple[Any, Any, dict]:
        del fn, args, options, state, tags, result
        return y, aux, {}
