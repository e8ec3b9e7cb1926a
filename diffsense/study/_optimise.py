"""The main job, `optimise(problem)`: the one-parameter job or the many-parameter one, and the
ODD sensitivity of its answer when asked for.

    result = optimise(problem)    # stepped sweep + continuous solve + what the figures draw
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

from diffsense.metrics import Objective
from diffsense.runtime import initialize
from diffsense.study._box_job import optimise_box
from diffsense.study._line_job import Progress, optimise_line
from diffsense.study._problem import Problem
from diffsense.study._result import Result
from diffsense.study._sensitivity import check_theta, sensitivities


def optimise(problem: Problem, *, E: Objective | None = None, predictor: Any = None, figures: bool = True,
             progress: Progress | None = None, on_evaluation: Callable[[dict], None] | None = None,
             sensitivity: tuple[str, ...] = (), distributed: bool | Mapping[str, Any] = False,
             judge: bool | None = None) -> Result:
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
    """
    judge = E is None if judge is None else judge
    say = progress or (lambda message: None)
    if distributed:
        initialize(**(dict(distributed) if isinstance(distributed, Mapping) else {}))
    if sensitivity:  # refused before any work, not after the solve
        check_theta(problem, sensitivity)
    if len(problem.params) != 1 or problem.question.cost_weight > 0:
        return optimise_box(problem, E, predictor, say, on_evaluation, judge)
    out, E = optimise_line(problem, E, predictor, figures, say, on_evaluation, judge)
    if sensitivity:
        how = ("re-solving on E_ref at theta -+ delta, about 36 evaluations each"
               if (out.reference or {}).get("answer_on") == "E_ref" else "implicit function theorem")
        say(f"{problem.sensor_kind}: dr*/dtheta for {', '.join(sensitivity)} ({how})")
        values, notes = sensitivities(problem, out, sensitivity, E=E)
        solved = dataclasses.replace(out.solve, notes=(*out.solve.notes, *notes))
        out = dataclasses.replace(out, sensitivity=values, solve=solved)
    return out
