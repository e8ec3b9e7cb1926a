"""The main job, `optimise(problem)`: the one-parameter job or the many-parameter one, and the
ODD sensitivity of its answer when asked for.

    result = optimise(problem)    # stepped sweep + continuous solve + what the figures draw

With `problem.traffic.target_ci`, the one-parameter job runs again with twice the variants until
the decision's interval is narrow enough or clear (`decision_interval`), up to a cap.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

from diffsense.metrics import Objective
from diffsense.runtime import InputError, initialize
from diffsense.study._box_job import optimise_box
from diffsense.study._line_job import Progress, optimise_line
from diffsense.study._problem import Problem
from diffsense.study._result import Result
from diffsense.study._sensitivity import check_theta, sensitivities

# The most variants per scenario `target_ci` doubles to (8, 16, ..., 128: five runs at most from 8).
TARGET_CI_MAX_VARIANTS = 128


def optimise(problem: Problem, *, E: Objective | None = None, predictor: Any = None, figures: bool = True,
             progress: Progress | None = None, on_evaluation: Callable[[dict], None] | None = None,
             sensitivity: tuple[str, ...] = (), distributed: bool | Mapping[str, Any] = False,
             judge: bool | None = None, max_variants: int = TARGET_CI_MAX_VARIANTS) -> Result:
    """The main job: argmin of E over the problem's box, cross-checked by the stepped sweep.

    One-parameter problems: the stepped sweep on E_hard, then the continuous solve inside the
    best step's bracket (`diffsense.solve.solve`; the hard estimator searches an inner grid
    instead), the answer chosen on E_hard. With `figures`, the evaluations the figures draw
    are made too (`Result.curves`); with `problem.solver.dense_check`, a dense grid of the reference E_ref.
    `E` reuses an already built `objective(problem)`; `predictor` an already loaded predictor.
    `sensitivity` names ODD parameters ("rain_mm_h", ...) whose dr*/dtheta is computed at the
    answer (`diffsense.sensitivity`) and kept in `Result.sensitivity`.
    `distributed` (True, or {"coordinator", "num_processes", "process_id", "join_timeout_s"})
    joins a multi-process run first (`diffsense.runtime.initialize`, bounded by the join timeout:
    DIFFSENSE_JOIN_TIMEOUT_S, default 60 s; before any JAX computation): every process
    calls `optimise` with the same problem and gets the same result.
    `on_evaluation(event)` is called after every objective evaluation the run makes, with
    {"kind": "soft" | "hard" | "reference", "E_m", "tau", "done", "planned"} (for progress displays).
    `judge` evaluates E_ref at the answer on a fresh seed's scene variants, noise and detection
    draws (`Result.judged`, result.json's "judged"): the answer judged on data it was not chosen
    on. By default (None) it does so when `optimise` builds the objective itself; an `E` given is
    the caller's own data, with no fresh sample known to it.
    `problem.traffic.target_ci` M [m] (one parameter, no `E`): the job is run with
    `problem.traffic.variants` variants per scenario (at least 2), then twice as many, ... up to
    `max_variants` (default `TARGET_CI_MAX_VARIANTS`), until the decision's interval
    (`decision_interval`) has a half-width under M or excludes 0; the last run is returned, its
    `intervals["target_ci"]` (result.json's "target_ci") saying how many variants it used.
    """
    judge = E is None if judge is None else judge
    say = progress or (lambda message: None)
    if distributed:
        initialize(**(dict(distributed) if isinstance(distributed, Mapping) else {}))
    if problem.traffic.target_ci is not None and (len(problem.params) != 1 or problem.question.cost_weight > 0):
        raise InputError("target_ci is for the one-parameter job: a many-parameter solve reports no intervals yet")
    if sensitivity:  # refused before any work, not after the solve
        check_theta(problem, sensitivity)
    if len(problem.params) != 1 or problem.question.cost_weight > 0:
        return optimise_box(problem, E, predictor, say, on_evaluation, judge)
    if problem.traffic.target_ci is not None:
        if E is not None:
            raise InputError("target_ci builds the objective again with more variants: give no E with it")
        out, E, problem = _to_target(problem, predictor, figures, say, on_evaluation, judge, max_variants)
    else:
        out, E = optimise_line(problem, E, predictor, figures, say, on_evaluation, judge)
    if sensitivity:
        how = ("re-solving on E_ref at theta -+ delta, about 36 evaluations each"
               if (out.reference or {}).get("answer_on") == "E_ref" else "implicit function theorem")
        say(f"{problem.sensor_kind}: dr*/dtheta for {', '.join(sensitivity)} ({how})")
        values, notes = sensitivities(problem, out, sensitivity, E=E)
        solved = dataclasses.replace(out.solve, notes=(*out.solve.notes, *notes))
        out = dataclasses.replace(out, sensitivity=values, solve=solved)
    return out


def decision_interval(result: Result) -> tuple[str, list[float] | None, bool]:
    """The interval the one-parameter answer is decided by: the paired difference of the
    second-best sweep step against the best (its comparison in `result.intervals`), or, with one
    step, the answer's own E_ci. Returns what it is, [lo, hi] [m] (None without intervals) and
    whether it is a difference (one that excludes 0 is a clear decision)."""
    ci = result.intervals or {}
    steps = [c for c in ci.get("comparisons") or [] if not str(c["a"]).startswith("r* ")]
    if steps:
        second = min(steps, key=lambda c: c["diff_m"])
        return f"{second['a']} against {second['b']}", second["ci"], True
    return "E at r*", ci.get("E_ci"), False


def _to_target(problem: Problem, predictor: Any, figures: bool, say: Progress, on_evaluation, judge: bool,
               max_variants: int) -> tuple[Result, Objective, Problem]:
    """The one-parameter job at doubling variant counts until the decision's interval meets
    `problem.traffic.target_ci` (`optimise`); the last run, its objective and problem."""
    target, n, tried = problem.traffic.target_ci, max(problem.traffic.variants, 2), []
    while True:
        problem = problem.replace(variants=n)
        out, E = optimise_line(problem, None, predictor, figures, say, on_evaluation, judge)
        what, ci, difference = decision_interval(out)
        half = None if ci is None else (ci[1] - ci[0]) / 2.0
        clear = difference and ci is not None and (ci[0] > 0.0 or ci[1] < 0.0)
        met = half is not None and (half < target or clear)
        tried.append({"variants": n, "half_width_m": half, "clear": clear})
        last = met or 2 * n > max_variants
        say(f"target CI {target:g} m: {n} variants per scenario, {what} half-width "
            + ("none" if half is None else f"{half:.3f} m") + (", clear" if clear else "")
            + ("; met" if met else ("; not met at the cap" if last else f"; doubling to {2 * n}")))
        if last:
            record = {"m": target, "variants_used": n, "met": met, "decision": what, "half_width_m": half,
                      "clear": clear, "cap": max_variants, "tried": tried}
            return dataclasses.replace(out, intervals={**(out.intervals or {}), "target_ci": record}), E, problem
        n *= 2
