"""What an answer claims: the near-optimal set and flags that say when r* misleads.

From every hard evaluation a run made (sweep, solve, figures, dense check), sorted by r:
- near_optimal: the intervals of r whose E_hard lies within `tolerance_m` of the best, where
  tolerance_m = max(NEAR_OPTIMAL_ABS_M, NEAR_OPTIMAL_REL x best E): any r in them is as good as r*
  to that tolerance (between two evaluated points the interval is an interpolation: E was not
  evaluated there);
- "pressing_on_bound": r* lies within 2 % of the interval's width from a bound: the optimum may lie
  outside the interval; widen it to see;
- "flat": the near-optimal interval holding r* spans at least 10 % of the interval's width: E
  barely changes there, so r* is one of many equally good values.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

NEAR_OPTIMAL_ABS_M = 0.01  # 1 cm: below what the hard objective resolves between neighbouring steps
NEAR_OPTIMAL_REL = 0.005  # 0.5 % of E
BOUND_FRACTION = 0.02
FLAT_FRACTION = 0.10


def near_optimal(points: Sequence[tuple[float, float]], lo: float, hi: float, r_star: float) -> dict[str, Any]:
    """{"near_optimal": {"tolerance_m", "intervals"}, "flags": [...]} from (r, E_hard) points."""
    pts = sorted(points)
    best = min(e for _, e in pts)
    tol = max(NEAR_OPTIMAL_ABS_M, NEAR_OPTIMAL_REL * best)
    intervals: list[list[float]] = []
    run: list[float] | None = None
    for r, e in pts:
        if e <= best + tol:
            run = [r, r] if run is None else [run[0], r]
        elif run is not None:
            intervals.append(run)
            run = None
    if run is not None:
        intervals.append(run)
    flags = []
    width = hi - lo
    if min(r_star - lo, hi - r_star) <= BOUND_FRACTION * width:
        flags.append("pressing_on_bound")
    holding = next((iv for iv in intervals if iv[0] <= r_star <= iv[1]), None)
    if holding is not None and holding[1] - holding[0] >= FLAT_FRACTION * width:
        flags.append("flat")
    return {"near_optimal": {"tolerance_m": tol, "intervals": intervals}, "flags": flags}


def explain(flags: Sequence[str], intervals: Sequence[Sequence[float]], unit: str) -> list[str]:
    """The flags in plain words, for the printed summary."""
    words = []
    if "pressing_on_bound" in flags:
        words.append("r* presses on a bound of the interval: the best value may lie outside it; widen the interval")
    if "flat" in flags:
        spans = ", ".join(f"[{a:.4g}, {b:.4g}]" + (f" {unit}" if unit else "") for a, b in intervals)
        words.append(f"E is flat around r*: every evaluated value in {spans} is as good to the tolerance")
    return words
