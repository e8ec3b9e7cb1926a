"""The one-parameter search on the answer objective itself: the stepped sweep, then Brent's
bounded minimisation (golden section with parabolic steps) inside the best step's bracket.

Under a probabilistic detection law the answer objective is E_ref, the expectation of the hard
objective over detection draws, and in one parameter a value of it is cheaper than a gradient
and more faithful than a relaxed one: a relaxed slope smooths away a minimum narrower than its
temperatures (radar HFOV 5-60 deg has a dip at 10 deg narrower than 2 deg, docs: solver). Brent needs
no derivative and keeps the best point it has seen, so the answer is never worse than the best
step.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import Any

from diffsense.solve._solve_config import SolveResult
from diffsense.solve._steps import (
    SweepPoint,
    best_step,
    bracket_around,
    check_interval,
    check_steps,
    default_steps,
    sweep,
)

_GOLDEN = 0.5 * (3.0 - math.sqrt(5.0))  # the golden section's shorter share of a bracket
_SQRT_EPS = math.sqrt(2.2e-16)


def brent_minimise(f: Callable[[float], float], lower: float, upper: float, *, xtol: float,
                   max_evaluations: int, start: tuple[float, float] | None = None
                   ) -> tuple[float, float, int]:
    """(x, f(x), evaluations): a local minimum of `f` on (lower, upper) by Brent's method.

    Each step fits a parabola through the three best points and steps to its vertex where that
    is inside the bracket and shrinks the step before last by half; otherwise it takes a golden
    section of the larger side. It stops when the bracket around the best point is within
    2 (xtol / 3 + sqrt(eps) |x|) of it, or after `max_evaluations` calls of `f`.

    Args:
        f: the objective (a host float of a host float).
        lower, upper: the bracket (lower < upper).
        xtol: absolute tolerance on x.
        max_evaluations: calls of `f` at most (>= 1).
        start: (x0, f(x0)) already known, x0 strictly inside the bracket: the search starts there
            without evaluating it. Default: the golden point of the bracket.
    """
    a, b = float(lower), float(upper)
    if start is not None and a < start[0] < b:
        x, fx = float(start[0]), float(start[1])
        used = 0
    else:
        x = a + _GOLDEN * (b - a)
        fx, used = float(f(x)), 1
    v = w = x
    fv = fw = fx
    d = e = 0.0
    while used < max_evaluations:
        mid = 0.5 * (a + b)
        tol = _SQRT_EPS * abs(x) + xtol / 3.0
        if abs(x - mid) <= 2.0 * tol - 0.5 * (b - a):
            break
        d, e = _next_step(a, b, x, w, v, fx, fw, fv, d, e, tol)
        u = x + (d if abs(d) >= tol else math.copysign(tol, d))
        fu = float(f(u))
        used += 1
        if fu <= fx:
            a, b = (a, x) if u < x else (x, b)
            v, fv, w, fw, x, fx = w, fw, x, fx, u, fu
            continue
        a, b = (u, b) if u < x else (a, u)
        if fu <= fw or w == x:
            v, fv, w, fw = w, fw, u, fu
        elif fu <= fv or v in (x, w):
            v, fv = u, fu
    return x, fx, used


def _next_step(a, b, x, w, v, fx, fw, fv, d, e, tol) -> tuple[float, float]:
    """(d, e): Brent's next step from x and the step before last; a parabolic step where it is
    acceptable, else a golden section of the larger side of the bracket."""
    mid = 0.5 * (a + b)
    if abs(e) > tol:
        r = (x - w) * (fx - fv)
        q = (x - v) * (fx - fw)
        p = (x - v) * q - (x - w) * r
        q = 2.0 * (q - r)
        p, q = (-p, q) if q > 0 else (p, -q)
        if abs(p) < abs(0.5 * q * e) and q * (a - x) < p < q * (b - x):
            u = x + p / q
            if u - a < 2.0 * tol or b - u < 2.0 * tol:  # not closer than tol to an end
                return (tol if x < mid else -tol), d
            return p / q, d
    e = (b - x) if x < mid else (a - x)
    return _GOLDEN * e, e


def brent_solve(
    e_answer: Callable[[float], Any],
    interval: tuple[float, float],
    *,
    steps: Sequence[float] | None = None,
    sweep_points: Sequence[SweepPoint] | None = None,
    max_evaluations: int = 20,
    xtol_rel: float = 1e-3,
    answer_name: str = "E_ref",
) -> SolveResult:
    """argmin of `e_answer(r) -> E [m]` over `interval`: the stepped sweep, then Brent inside the
    best step's bracket, started from that step where it is inside, with at most
    `max_evaluations` values (the sweep's not counted). The answer is the best point seen, so
    never worse than the best step. E_soft fields hold the answer objective's values (no soft
    objective is used); `wall_s` times the sweep and the search [s]. `sweep_points`: an
    already evaluated sweep (then `steps` is ignored)."""
    lo, hi = check_interval(*interval)
    t0 = time.perf_counter()
    if sweep_points is None:
        grid = check_steps(default_steps(lo, hi) if steps is None else steps, lo, hi)
        sweep_points = sweep(e_answer, None, grid)
    points = tuple(sweep_points)
    t1 = time.perf_counter()
    k = best_step(points)
    best = points[k]
    lower, upper = bracket_around(points, k, lo, hi)
    r, e, used = brent_minimise(lambda x: float(e_answer(x)), lower, upper, xtol=xtol_rel * (hi - lo),
                                max_evaluations=max_evaluations, start=(best.r, best.E_hard))
    notes = [f"Brent on {answer_name} inside the best step's bracket [{lower:.6g}, {upper:.6g}]: "
             f"{used} evaluations"]
    if not e < best.E_hard:
        r, e = best.r, best.E_hard
    if used >= max_evaluations:
        notes.append(f"the search stopped on its budget of {max_evaluations} evaluations")
    return SolveResult(
        r_star=float(r), E_soft_star=float(e), E_hard_star=float(e), sweep=points,
        evaluations={"objective": used, "gradient": 0}, on_bound=r in (lo, hi), bracket=(lower, upper),
        tau_schedule=(), levels=(), notes=tuple(notes), interval=(lo, hi),
        wall_s={"sweep": t1 - t0, "solve": time.perf_counter() - t1},
    )

