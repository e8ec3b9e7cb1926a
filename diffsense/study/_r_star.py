"""How far r* would move with other traffic: r* re-picked on each scene resample among points
where E was evaluated (`diffsense.metrics.argmin_ci`), on points made dense where the picks fall.

A resample can only pick a point that was evaluated, so the interval is resolved to them. The
refinement adds points across the span the picks reach (from the point below the interval to
the one above it) until neighbouring points there lie no further apart than REFINE_RESOLUTION
of the parameter's interval, or a quarter of r*'s own interval if that is wider: at most
REFINE_ROUNDS rounds of REFINE_POINTS points, each one evaluation of the answer's E.

One parameter (`r_star_interval`): the points are every point the job evaluated E at (sweep
steps, the solve's points, the polish, the figures'). Many parameters (`box_r_star_interval`):
per parameter, its axis through r*, the others held at r*, with AXIS_POINTS points evenly across
its bounds to begin with. That interval is conditional: it says how far r*'s value of one
parameter would move were the others fixed at theirs, not how the others would move with it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from diffsense.metrics import LEVEL, RESAMPLES, SceneSums, argmin_ci
from diffsense.solve import Evaluator

REFINE_ROUNDS = 2
REFINE_POINTS = 8
REFINE_RESOLUTION = 0.01
AXIS_POINTS = 9  # each axis of a many-parameter answer to begin with: its bounds and 7 between

CONDITIONAL_CAVEAT = ("conditional: each parameter's interval holds the others at r*, so it leaves out how they would "
                      "move with it; read them one at a time, not as a joint region: on a two-parameter radar problem "
                      "each held the large-sample r* in 77-87 % of seeds, both at once in 67-70 % (docs/uncertainty.md)")

Interval = tuple[list[float] | None, float | None, int]


def _picked_span(points: np.ndarray, ci: tuple[float, float]) -> tuple[int, int]:
    """The indices of the evaluated points bounding the span r*'s interval could reach: from the
    point below the interval's lower end to the one above its upper end (a resample may prefer
    any r between the last point it picked and the next one out)."""
    i0 = int(np.searchsorted(points, ci[0], side="left")) - 1
    i1 = int(np.searchsorted(points, ci[1], side="right"))
    return max(i0, 0), min(i1, points.size - 1)


def _refined(values: set[float], sums_at: Callable[[float], SceneSums | None], groups: np.ndarray, *, seed: int,
             width: float, offset_at: Callable[[float], float] | None = None) -> Interval:
    """`argmin_ci` over the points `values` (one-dimensional: r, or one parameter's value on its
    axis), `sums_at(v)` their E's `SceneSums` and `offset_at(v)` a term added to E there [m],
    refined as the module docstring says (`width`: the parameter's interval). Returns the interval
    [lo, hi] (None where it cannot be estimated), its resolution (the widest gap between
    neighbouring points across the span it could reach) and the points' count."""
    values, rounds = set(values), 0
    while True:
        points = np.asarray(sorted(values), np.float64)
        sums = [sums_at(float(v)) for v in points]
        if not points.size or any(s is None for s in sums):
            return None, None, int(points.size)
        offset = None if offset_at is None else np.array([offset_at(float(v)) for v in points])
        ci = argmin_ci(points, sums, groups, level=LEVEL, resamples=RESAMPLES, seed=seed, offset_m=offset)
        if ci is None:
            return None, None, int(points.size)
        i0, i1 = _picked_span(points, ci)
        resolution = float(np.max(np.diff(points[i0:i1 + 1]))) if i1 > i0 else None
        wanted = max(REFINE_RESOLUTION * width, 0.25 * (ci[1] - ci[0]))
        if resolution is None or resolution <= wanted or rounds == REFINE_ROUNDS:
            return list(ci), resolution, int(points.size)
        rounds += 1
        values |= {float(v) for v in np.linspace(points[i0], points[i1], REFINE_POINTS + 2)[1:-1]}


def r_star_interval(ev: Evaluator, groups: np.ndarray, *, of_reference: bool, seed: int,
                    interval: tuple[float, float]) -> Interval:
    """A one-parameter answer's r* interval: `argmin_ci` over every point the job evaluated the
    answer's E at (E_ref, or E_hard where not `of_reference`), refined where the picks fall
    (module docstring; `interval` the parameter's). Returns ([lo, hi] or None, its resolution,
    the points' count)."""
    evaluated = ev.reference_points() if of_reference else ev.hard_points()
    return _refined({x[0] for x in evaluated}, lambda r: ev.scene_sums(r, of_reference), groups, seed=seed,
                    width=interval[1] - interval[0])


def box_r_star_interval(ev: Evaluator, x: Sequence[float], bounds: Sequence[tuple[float, float]],
                        groups: np.ndarray, *, of_reference: bool, seed: int,
                        offset_at: Callable[[np.ndarray], float] | None = None) -> list[Interval]:
    """A many-parameter answer's r* interval, per parameter (in `ev.objective.names` order): the
    one-parameter interval along that parameter's axis through r* (`x`), the others held at r*,
    from AXIS_POINTS points evenly across its `bounds` and r*'s own value, refined where the picks
    fall. `offset_at(x)` [m] is added to E at each point (lambda x cost: the pick is J's). One
    (interval, resolution, points) per parameter."""
    x = np.asarray(x, np.float64)

    def axis(i: int) -> Interval:
        def at(v: float) -> np.ndarray:
            y = x.copy()
            y[i] = v
            return y

        lo, hi = (float(b) for b in bounds[i])
        values = {float(v) for v in np.linspace(lo, hi, AXIS_POINTS)} | {float(x[i])}
        offset: Any = None if offset_at is None else (lambda v: float(offset_at(at(v))))
        return _refined(values, lambda v: ev.scene_sums(at(v), of_reference), groups, seed=seed, width=hi - lo,
                        offset_at=offset)

    return [axis(i) for i in range(x.size)]
