"""The search of the hard estimator, which has no gradient: the stepped sweep, then an even hard
grid inside the best step's bracket with the continuous solve's evaluation budget."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from diffsense.solve._continuous import SolveResult
from diffsense.solve._steps import (
    best_step,
    bracket_around,
    check_interval,
    check_steps,
    default_steps,
    sweep,
)


def hard_grid_solve(
    e_hard: Callable[[float], Any],
    interval: tuple[float, float],
    *,
    steps: Sequence[float] | None = None,
    max_evaluations: int = 20,
) -> SolveResult:
    """argmin over the sweep's steps and `max_evaluations` evenly spaced points strictly inside
    the best step's bracket, all on `e_hard(r) -> E [m]`. E_soft fields hold E_hard (there is no
    soft objective); `evaluations["objective"]` counts the inner points (the sweep excluded);
    `wall_s` times the sweep and the inner grid [s]."""
    lo, hi = check_interval(*interval)
    grid = check_steps(default_steps(lo, hi) if steps is None else steps, lo, hi)
    t0 = time.perf_counter()
    points = sweep(e_hard, lambda r, tau: float(e_hard(r)) ** 2, grid)
    t1 = time.perf_counter()
    k = best_step(points)
    b_lo, b_hi = bracket_around(points, k, lo, hi)
    inner = [float(r) for r in np.linspace(b_lo, b_hi, max_evaluations + 2)[1:-1]]
    e_best, r_best = min([(points[k].E_hard, points[k].r)] + [(float(e_hard(r)), r) for r in inner])
    t2 = time.perf_counter()
    return SolveResult(
        r_star=r_best, E_soft_star=e_best, E_hard_star=e_best, sweep=points,
        evaluations={"objective": len(inner), "gradient": 0}, on_bound=r_best in (lo, hi),
        bracket=(b_lo, b_hi), tau_schedule=(), levels=(),
        notes=("hard estimator: no gradient; r* is the best of the sweep and an even hard grid "
               f"of {len(inner)} points inside the best bracket",),
        interval=(lo, hi), wall_s={"sweep": t1 - t0, "solve": t2 - t1},
    )
