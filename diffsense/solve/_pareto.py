"""The cost-weight sweep: one box solve per weight lambda in J = E + lambda * cost, and which
answers are Pareto-optimal in (E_hard, cost)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any

from diffsense.solve._box import box_solve
from diffsense.solve._box_config import BoxConfig, BoxResult
from diffsense.solve._box_fns import BoxFunctions


def pareto_sweep(fns: BoxFunctions, bounds: Any, weights: Sequence[float], config: BoxConfig = BoxConfig(),
                 extra_starts: Sequence[Sequence[float]] = (),
                 on_solved: Callable[[int, float, BoxResult], None] | None = None,
                 ) -> tuple[tuple[BoxResult, ...], tuple[bool, ...]]:
    """One box solve per cost weight, in the order given, and which answers are Pareto-optimal in
    (E_hard, cost). Each solve after the first is warm-started: the previous weight's answer joins
    its sample (and `extra_starts`); the evaluations are memoised in `fns`, so the coarse sample is
    paid for once. `on_solved(k, weight, result)` is called after each solve."""
    results: list[BoxResult] = []
    for k, w in enumerate(weights):
        warm = [[results[-1].x_star[n] for n in fns.names]] if results else []
        results.append(box_solve(fns, bounds, dataclasses.replace(config, cost_weight=float(w)),
                                 extra_starts=[*warm, *extra_starts]))
        if on_solved is not None:
            on_solved(k, float(w), results[-1])
    return tuple(results), _pareto_front([(r.E_hard, r.cost) for r in results])


def _pareto_front(points: Sequence[tuple[float, float]]) -> tuple[bool, ...]:
    """Per (E, cost) point: True unless another point is no worse in both and differs."""
    return tuple(not any(q[0] <= p[0] and q[1] <= p[1] and q != p for q in points) for p in points)
