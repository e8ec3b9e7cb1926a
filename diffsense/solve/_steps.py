"""The stepped sweep: the paper's discrete grid of parameter values, evaluated hard and soft.

The paper sweeps HFOV = 30, 60, ..., 180 deg (its Table III). For any other parameter interval
`default_steps` picks 6 to 8 evenly spaced values including both ends, preferring the count
whose spacing is the roundest number (so [30, 180] gives the paper's six steps).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence

import numpy as np

from diffsense.runtime import InputError

# The paper's HFOV steps [deg] (Table III, both sensors).
PAPER_HFOV_STEPS_DEG = (30.0, 60.0, 90.0, 120.0, 150.0, 180.0)


@dataclasses.dataclass(frozen=True)
class SweepPoint:
    """One step of the sweep.

    Attributes:
        r: the parameter value (the objective's own units).
        E_hard: E_RMSE with hard detections [m].
        E_soft: E_RMSE with soft detections at the final temperature [m].
    """

    r: float
    E_hard: float
    E_soft: float


def check_interval(lo: float, hi: float) -> tuple[float, float]:
    """The interval as floats; InputError unless both are finite and lo < hi."""
    lo, hi = float(lo), float(hi)
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise InputError(f"interval [{lo}, {hi}] is not finite")
    if not lo < hi:
        raise InputError(f"interval [{lo}, {hi}]: LO must be smaller than HI")
    return lo, hi


def _significant_digits(x: float) -> int:
    """How many significant decimal digits `x` needs (up to 12)."""
    for digits in range(1, 13):
        if math.isclose(float(f"{x:.{digits}g}"), x, rel_tol=1e-9, abs_tol=0.0):
            return digits
    return 13


def default_steps(lo: float, hi: float, counts: Sequence[int] = (6, 7, 8)) -> np.ndarray:
    """Evenly spaced steps over [lo, hi], both ends included, float64 [n].

    Of the candidate `counts`, the one whose spacing needs the fewest significant digits wins
    (ties: fewer steps). Give lo and hi in the units the steps should be round in (degrees for
    an angle) and convert afterwards.
    """
    lo, hi = check_interval(lo, hi)
    if not counts or min(counts) < 2:
        raise InputError(f"step counts {tuple(counts)} must all be at least 2")
    best = min(counts, key=lambda n: (_significant_digits((hi - lo) / (n - 1)), n))
    return np.linspace(lo, hi, best)


def check_steps(steps: Sequence[float], lo: float, hi: float) -> np.ndarray:
    """The steps as a sorted float64 array; InputError if any lies outside [lo, hi] or repeats."""
    arr = np.asarray(steps, dtype=np.float64).reshape(-1)
    if arr.size < 2:
        raise InputError(f"need at least 2 steps, got {arr.size}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"steps {arr.tolist()} contain a non-finite value")
    arr = np.sort(arr)
    if arr[0] < lo or arr[-1] > hi:
        raise InputError(f"steps {arr.tolist()} leave the interval [{lo}, {hi}]")
    if np.any(np.diff(arr) <= 0):
        raise InputError(f"steps {arr.tolist()} repeat a value")
    return arr


def sweep(
    e_hard: Callable[[float], float],
    e2_soft: Callable[[float, float], float] | None,
    steps: Sequence[float],
    *,
    tau: float = 1.0,
) -> tuple[SweepPoint, ...]:
    """Evaluate E_hard(r) and E_soft(r, tau) = sqrt(e2_soft(r, tau)) at every step.

    `e_hard(r)` returns E in metres; `e2_soft(r, tau)` returns E^2 in m^2. Costs len(steps)
    hard and len(steps) soft objective evaluations. `e2_soft` None: the soft value is the hard
    objective's own (straight-through), so E_soft is E_hard and no soft evaluation is made.
    """
    points = []
    for r in np.asarray(steps, dtype=np.float64).reshape(-1):
        e_h = float(e_hard(float(r)))
        e_s = e_h if e2_soft is None else math.sqrt(max(float(e2_soft(float(r), tau)), 0.0))
        points.append(SweepPoint(r=float(r), E_hard=e_h, E_soft=e_s))
    return tuple(points)


def best_step(points: Sequence[SweepPoint]) -> int:
    """Index of the step with the smallest E_hard (ties: the smaller E_soft, then the first)."""
    if not points:
        raise InputError("the sweep has no steps")
    return min(range(len(points)), key=lambda i: (points[i].E_hard, points[i].E_soft, i))


def bracket_around(
    points: Sequence[SweepPoint], index: int, lo: float, hi: float
) -> tuple[float, float]:
    """The neighbouring steps of step `index` (the interval's ends beyond the first/last step)."""
    left = points[index - 1].r if index > 0 else lo
    right = points[index + 1].r if index + 1 < len(points) else hi
    return max(left, lo), min(right, hi)
