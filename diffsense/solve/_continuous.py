"""The continuous solve: the best r over an interval, refined from the stepped sweep.

Strategy:
1. the sweep's best step on the HARD objective gives a bracket: its neighbouring steps;
2. inside the bracket, the minimum of the SOFT objective E^2(r, tau) is found as the root of
   dE^2/dr (the optimistix solver `BracketedSecant`, or bisection), for each temperature of a
   continuation schedule, largest first, each level warm-started from the one before;
3. the final answer is chosen by the HARD objective: the soft optimum is kept when it is at
   least as good as the best step, otherwise the other candidates (earlier levels' optima, the
   best step itself) are compared and `notes` says why the answer is not the soft optimum. So
   E_hard(r*) <= min over steps of E_hard always holds. Where the soft value is the hard
   objective's own and only its gradient relaxed (`soft_value_is_answer`), every gradient
   evaluation's point is a candidate too;
4. a hard polish: a compass search on E_hard around that answer with the evaluations left in
   the budget (at most `SolveConfig.hard_polish`; `reserve_polish` keeps them back from step 2). The soft objective cannot see the hard one's
   fine structure (a vehicle toggling in and out of the FOV at one instant moves E_hard by
   centimetres over a fraction of a degree); a few hard probes near r* settle it, and a probe is
   only accepted when it is strictly better, so this step never makes the answer worse.

`SolveConfig.method = "brent"` replaces steps 2-4 by Brent's bounded minimisation of the hard
(answer) objective's values inside the bracket (`_brent.brent_solve`).

E^2 is optimised (the gradient of sqrt is NaN at 0); E = sqrt(E^2) is reported. Every objective
and gradient evaluation of step 2-3 is counted against `SolveConfig.max_evaluations`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

from diffsense.solve._brent import brent_solve
from diffsense.solve._levels import (
    Counted,
    e_from_e2,
    hard_polish_walk,
    level_bisection,
    level_secant,
)
from diffsense.solve._solve_config import (
    RESERVE_PER_LEVEL,
    LevelResult,
    SolveConfig,
    SolveResult,
    host_array,
    outer_dtype,
)
from diffsense.solve._steps import (
    SweepPoint,
    best_step,
    bracket_around,
    check_interval,
    check_steps,
    default_steps,
    sweep,
)

__all__ = ["LevelResult", "SolveConfig", "SolveResult", "solve"]


def solve(
    e2_soft: Callable[[Any, Any], Any],
    e_hard: Callable[[Any], Any],
    interval: tuple[float, float],
    *,
    steps: Sequence[float] | None = None,
    config: SolveConfig = SolveConfig(),
    sweep_points: Sequence[SweepPoint] | None = None,
    value_and_grad: Callable[[float, float], tuple[float, float]] | None = None,
    answer_name: str = "E_hard",
    soft_value_is_answer: bool = False,
) -> SolveResult:
    """Find argmin_r E over `interval`: stepped sweep, then the continuous solve (module doc).

    Args:
        e2_soft: `e2_soft(r, tau) -> E^2 [m^2]`, pure, differentiable in r with jax.grad.
        e_hard: `e_hard(r) -> E [m]`, pure, piecewise constant, no gradient needed.
        interval: (lo, hi) in the objective's units.
        steps: the sweep's steps (default: `default_steps(lo, hi)`).
        config: solver settings.
        sweep_points: an already evaluated sweep (then `steps` is ignored).
        value_and_grad: optional host function `(r, tau) -> (E^2, dE^2/dr)` (floats), used for
            every soft evaluation instead of tracing `e2_soft` (an objective compiled and
            memoised elsewhere, e.g. `Evaluator`); `e2_soft` is then never traced.
        answer_name: what the notes call the objective `e_hard` evaluates (the caller knows:
            "E_ref" when it is the expectation over detection draws).
        soft_value_is_answer: the soft objective's value is the answer objective's own, its
            gradient alone relaxed (straight-through under a probabilistic law): the sweep
            reads E_soft off E_hard, every gradient evaluation's point is an answer candidate
            too, and the polish starts from the best of them when it beats the levels' answer.

    Returns:
        A SolveResult. Raises InputError on a bad interval/steps/config and FloatingPointError
        if the objective's gradient is not finite.
    """
    lo, hi = check_interval(*interval)
    dtype = outer_dtype(config.dtype)
    if config.method == "brent":
        return brent_solve(lambda r: e_hard(host_array(r, dtype)), (lo, hi), steps=steps, sweep_points=sweep_points,
                           max_evaluations=config.max_evaluations, xtol_rel=config.xtol_rel, answer_name=answer_name)
    taus = tuple(float(t) for t in config.tau_schedule)
    t0 = time.perf_counter()
    if sweep_points is None:
        grid = check_steps(default_steps(lo, hi) if steps is None else steps, lo, hi)
        sweep_points = _sweep(e2_soft, e_hard, grid, dtype, taus[-1], value_and_grad, soft_value_is_answer)
    sweep_points = tuple(sweep_points)
    t1 = time.perf_counter()

    k = best_step(sweep_points)
    best = sweep_points[k]
    lower, upper = bracket_around(sweep_points, k, lo, hi)
    counted = Counted(e2_soft, e_hard, dtype, value_and_grad, keep_values=soft_value_is_answer)
    xtol = config.xtol_rel * (hi - lo)
    notes: list[str] = []
    levels = _continuation(counted, best.r, (lower, upper), taus, config, xtol, notes)
    r_star, e_hard_star = _on_hard(counted, levels, best, (lo, hi), config, answer_name, notes)
    if soft_value_is_answer:
        r_star, e_hard_star = _best_seen(counted, r_star, e_hard_star, answer_name, notes, config.max_evaluations)
    # E_soft at a polished r* costs an evaluation kept back, unless it is the answer's own value.
    kept_back = 0 if soft_value_is_answer else 1
    probes = min(config.hard_polish, config.max_evaluations - counted.objective - counted.gradient - kept_back)
    if probes > 0:
        r_star, e_hard_star = _polish(counted, r_star, e_hard_star, (lower, upper), probes, xtol, answer_name, notes)
    step_hit = next((p for p in sweep_points if p.r == r_star), None)
    if step_hit:
        e_soft_star = step_hit.E_soft
    elif soft_value_is_answer:
        e_soft_star = e_hard_star
    else:
        e_soft_star = e_from_e2(counted.e2(r_star, taus[-1]))
    total = counted.objective + counted.gradient
    if total > config.max_evaluations:
        notes.append(f"{total} evaluations exceed the budget of {config.max_evaluations}")
    return SolveResult(
        r_star=float(r_star), E_soft_star=float(e_soft_star), E_hard_star=float(e_hard_star),
        sweep=sweep_points, evaluations={"objective": counted.objective, "gradient": counted.gradient},
        on_bound=r_star in (lo, hi), bracket=(float(lower), float(upper)), tau_schedule=taus,
        levels=tuple(levels), notes=tuple(notes), interval=(lo, hi),
        wall_s={"sweep": t1 - t0, "solve": time.perf_counter() - t1},
    )


def _sweep(e2_soft, e_hard, grid, dtype, tau: float, value_and_grad, soft_value_is_answer: bool
           ) -> tuple[SweepPoint, ...]:
    """The stepped sweep: E_hard at every step, and E_soft at `tau` beside it unless it is the
    same number (`soft_value_is_answer`)."""
    if soft_value_is_answer:
        soft = None
    elif value_and_grad is not None:
        soft = lambda r, tau: value_and_grad(float(r), float(tau))[0]
    else:
        soft = lambda r, tau: e2_soft(host_array(r, dtype), host_array(tau, dtype))
    return sweep(lambda r: e_hard(host_array(r, dtype)), soft, grid, tau=tau)


def _polish(counted: Counted, r_star: float, e_star: float, bracket: tuple[float, float], probes: int,
            xtol: float, answer_name: str, notes: list[str]) -> tuple[float, float]:
    """(r, E): the hard polish's answer from (r_star, e_star) inside the bracket; `notes` says
    when it moved."""
    r, e = hard_polish_walk(counted, r_star, e_star, *bracket, probes, xtol)
    if r != r_star:
        notes.append(
            f"hard polish: r={r_star:.6g} -> {r:.6g} lowered {answer_name} from "
            f"{e_star:.6g} to {e:.6g} m (the soft objective cannot resolve differences this fine)"
        )
    return r, e


def _continuation(counted: Counted, r0: float, bracket: tuple[float, float], taus: tuple[float, ...],
                  config: SolveConfig, xtol: float, notes: list[str]) -> list[LevelResult]:
    """The soft minimum at each temperature, largest first, each level started from the one
    before and given its share of the evaluation budget; `notes` gains what stopped a level."""
    lower, upper = bracket
    levels: list[LevelResult] = []
    y, probe = r0, 0.25 * (upper - lower)
    for i, tau in enumerate(taus):
        tol = min(xtol * tau / taus[-1], 0.125 * (upper - lower))
        used = counted.objective + counted.gradient
        later = len(taus) - 1 - i
        max_steps = config.max_evaluations - used - 2 - RESERVE_PER_LEVEL * later - config._polish_reserve
        if max_steps < 1:
            notes.append(f"budget spent before tau={tau:g}: continuation stopped early")
            break
        if config.method in ("auto", "secant"):
            r, n, bound, done = level_secant(
                counted, y, tau, lower, upper, probe, tol, max_steps, config.max_evaluations
            )
        else:
            (r, bound), n, done = level_bisection(counted, y, tau, lower, upper, tol, max_steps)
        if not done:
            notes.append(f"tau={tau:g}: stopped after {n} gradient evaluations (budget share)")
        probe = max(2.0 * tol, abs(r - y)) if levels else max(2.0 * tol, 0.0625 * (upper - lower))
        y = r
        levels.append(
            LevelResult(tau=tau, r=r, gradient_evaluations=n, bound=bound, converged=done)
        )
    return levels


def _best_seen(counted: Counted, r_star: float, e_star: float, answer_name: str,
               notes: list[str], budget: int) -> tuple[float, float]:
    """(r, E): the best point the gradient evaluations saw where its value, the answer
    objective's own, is lower than the answer's, confirmed on the answer objective while the
    budget has an evaluation left; else the answer."""
    seen = [(e, r) for r, e in counted.values_seen if e < e_star and r != r_star]
    if not seen or counted.objective + counted.gradient >= budget:
        return r_star, e_star
    _, r = min(seen)
    e = counted.hard(r)
    if not e < e_star:
        return r_star, e_star
    notes.append(f"a gradient evaluation saw a lower {answer_name} than the levels' answer r={r_star:.6g} "
                 f"({e_star:.6g} m): answer r={r:.6g} ({e:.6g} m)")
    return r, e


def _on_hard(counted: Counted, levels: list[LevelResult], best: SweepPoint, interval: tuple[float, float],
             config: SolveConfig, answer_name: str, notes: list[str]) -> tuple[float, float]:
    """(r, E_hard): the last level's soft minimum, or, where the hard objective is worse there
    than at the best step, the best on it of the levels' answers and that step."""
    r_soft = levels[-1].r if levels else best.r
    last = levels[-1] if levels else None
    if last is not None and last.bound != 0 and r_soft not in interval:
        notes.append(
            f"the soft minimum at tau={last.tau:g} presses on the bracket edge r={r_soft:.6g}: "
            f"beyond it the sweep's {answer_name} is worse than at the best step r={best.r:.6g}"
        )
    r_star, e_hard_star = r_soft, counted.hard(r_soft)
    if e_hard_star > best.E_hard:
        candidates = [(e_hard_star, 0, r_soft)]
        for level in levels[:-1]:
            spent = counted.objective + counted.gradient
            if level.r != r_soft and spent < config.max_evaluations - 1:
                candidates.append((counted.hard(level.r), 0, level.r))
        candidates.append((best.E_hard, 1, best.r))
        e_hard_star, _, r_star = min(candidates)
        notes.append(
            f"the soft optimum r={r_soft:.6g} has {answer_name}={candidates[0][0]:.6g} m, worse than the "
            f"best step r={best.r:.6g} ({best.E_hard:.6g} m): the soft objective and {answer_name} disagree "
            f"there; answer r={r_star:.6g} is the best of {len(candidates)} candidates on {answer_name}"
        )
    return r_star, e_hard_star

