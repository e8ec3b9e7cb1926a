"""The one-parameter job: the stepped sweep on E_hard, the continuous solve inside the best step's
bracket, and what the figures and the breakdown need, gathered into a `Result`."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any

import jax.numpy as jnp

from diffsense.metrics import Objective, is_deterministic
from diffsense.runtime import CompileClock
from diffsense.solve import (
    Evaluator,
    SolveConfig,
    default_steps,
    hard_grid_solve,
    near_optimal,
    solve,
)
from diffsense.study import _line_report as report
from diffsense.study._domain import domain_check, domain_note
from diffsense.study._intervals import breakdown_intervals, line_intervals
from diffsense.study._r_star import REFINE_POINTS, REFINE_ROUNDS
from diffsense.study._judge import judged
from diffsense.study._objective import objective, scenes_line
from diffsense.study._problem import Problem, problem_config
from diffsense.study._result import Result

Progress = Callable[[str], None]


def planned_evaluations(problem: Problem, sweep_soft: bool = True) -> int:
    """How many objective evaluations `optimise` plans (sweep, solve budget, figures, dense check, r*'s interval).
    `sweep_soft` False: the sweep reads E_soft off its E_ref (straight-through under a
    probabilistic law, or Brent on E_ref's values), one program per step instead of two."""
    (lo, hi), = problem.params.values()
    solver = problem.solver
    steps = len(solver.steps) if solver.steps is not None else len(default_steps(lo, hi))
    dense = 0 if solver.dense_check is None else int(math.ceil((hi - lo) / solver.dense_check - 1e-9)) + 1
    sweep_programs = (2 if sweep_soft else 1) * steps
    refine = REFINE_ROUNDS * REFINE_POINTS  # r*'s interval, at most
    return sweep_programs + solver.solve.max_evaluations + 2 + solver.extra_curve_points * 2 + dense + refine


def _evaluator(problem: Problem, E: Objective | None, predictor: Any, say: Progress,
               on_evaluation: Callable[[dict], None] | None, figures: bool) -> tuple[Objective, Evaluator]:
    """The problem's objective (built unless given) and its memoising, counting evaluator."""
    say(f"{scenes_line(problem)}; ground-truth predictions")
    E = objective(problem, predictor=predictor, progress=say) if E is None else E
    # the figures draw E_soft's slope at the sweep's steps, except where E_soft is E_ref (`curves`)
    by_values = _concrete_method(problem.solver.solve, is_deterministic(E.sensor)).method == "brent"
    planned = planned_evaluations(problem, sweep_soft=not (by_values or _soft_value_is_e_ref(E)))

    def counted(kind: str, e_m: float, tau: float) -> None:
        if on_evaluation is not None:
            done = sum(ev.counts.values()) + ev.reference_count
            on_evaluation({"kind": kind, "E_m": e_m, "tau": tau, "done": done, "planned": planned})

    ev = Evaluator(E, progress=counted)
    return E, ev


def _soft_value_is_e_ref(E: Objective) -> bool:
    """Straight-through under a probabilistic law: E_soft's value is E_ref itself, so the sweep
    reads it off its E_ref evaluation rather than running a value-and-gradient program, and
    every gradient evaluation's point is an answer candidate."""
    return E.estimator_kind == "straight-through" and not is_deterministic(E.sensor)


def _solve_line(ev: Evaluator, problem: Problem, on_hard: bool) -> Any:
    """The sweep and the continuous solve (the inner hard grid for the hard estimator) of a
    one-parameter problem, the answer judged on E_hard or, under a probabilistic law, E_ref."""
    (_, (lo, hi)), = problem.params.items()
    steps, config = problem.solver.steps, _concrete_method(problem.solver.solve, on_hard)
    if problem.question.estimator.kind == "hard":
        return hard_grid_solve(ev.e_hard, (lo, hi), steps=steps, max_evaluations=config.max_evaluations)
    e2_soft, e_hard = ev.solver_fns(jnp.float64 if config.dtype == "float64" else jnp.float32)
    # Under a probabilistic detection law the sweep, the answer and the polish are judged on
    # E_ref, the expectation the estimator approximates; under the threshold law E_ref is E_hard.
    e_answer = e_hard if on_hard else (lambda r: ev.e_reference(float(r)))
    return solve(e2_soft, e_answer, (lo, hi), steps=steps, config=config,
                 value_and_grad=ev.host_value_and_grad, answer_name="E_hard" if on_hard else "E_ref",
                 soft_value_is_answer=_soft_value_is_e_ref(ev.objective))


def _concrete_method(config: SolveConfig, on_hard: bool) -> SolveConfig:
    """The solve settings with method "auto" made concrete: Brent on E_ref's values where the
    answer is E_ref (a probabilistic law), the secant continuation on the soft objective where
    it is E_hard (the threshold law)."""
    if config.method != "auto":
        return config
    return dataclasses.replace(config, method="secant" if on_hard else "brent")


def optimise_line(problem: Problem, E: Objective | None, predictor: Any, figures: bool, say: Progress,
                  on_evaluation: Callable[[dict], None] | None, judge: bool = True) -> tuple[Result, Objective]:
    """`optimise` of a one-parameter problem (its docstring), and the objective it built or was given."""
    (name, (lo, hi)), = problem.params.items()
    spec, solver = problem.sensing.specs[name], problem.solver
    hard_only = problem.question.estimator.kind == "hard"
    with CompileClock() as clock:
        E, ev = _evaluator(problem, E, predictor, say, on_evaluation, figures)
        on_hard = hard_only or is_deterministic(E.sensor)
        domain = domain_check(E, getattr(E.predictor, "validation_rmse_m", None))
        if domain_note(domain):
            say("warning: " + domain_note(domain))
        say(f"{problem.sensor_kind}: stepped sweep and {'hard grid' if hard_only else 'continuous solve'} "
            f"of {name} over [{lo:g}, {hi:g}] {spec.unit}")
        result = _solve_line(ev, problem, on_hard)
        solve_counts = dict(ev.counts)
        say(f"{problem.sensor_kind}: r* = {result.r_star:.5g} {spec.unit}, "
            f"{'E_hard' if on_hard else 'E_ref'}(r*) = {result.E_hard_star:.4f} m")
        curves = report.curves(ev, E, result, lo, hi, solver.extra_curve_points, hard_only,
                               _soft_value_is_e_ref(E)) if figures else None
        parts = report.breakdowns(ev, result, on_hard)
        fresh = None
        if judge:
            say(f"{problem.sensor_kind}: judging r* on fresh scenes and draws")
            fresh = judged(problem, E, {name: result.r_star})
    figure_counts = {k: ev.counts[k] - solve_counts[k] for k in ev.counts}
    dense = None
    if solver.dense_check is not None:
        say(f"{problem.sensor_kind}: dense reference grid every {solver.dense_check:g} {spec.unit}")
        dense = report.dense_check(ev, result, lo, hi, solver.dense_check)
        result = dataclasses.replace(result, notes=(*result.notes, "dense check: " + dense["verdict"]))
    if domain_note(domain):
        result = dataclasses.replace(result, notes=(*result.notes, domain_note(domain)))
    answered = [(x[0], ev.e_hard(x[0])) for x in ev.hard_points()] if on_hard else \
        [(x[0], ev.e_reference(x[0])) for x in ev.reference_points()]
    answer = near_optimal(answered, lo, hi, result.r_star)
    before = {"hard": ev.counts["hard"], "reference": ev.reference_count}
    ci = line_intervals(ev, result, ev.e_hard(result.r_star) if on_hard else ev.e_reference(result.r_star),
                        of_reference=not on_hard, seed=problem.seed, unit=spec.unit, interval=(lo, hi),
                        recorded=problem.traffic.scenes is not None)
    interval_counts = {"hard": ev.counts["hard"] - before["hard"], "reference": ev.reference_count - before["reference"]}
    near = answer["near_optimal"] | {"indistinguishable": ci.pop("indistinguishable")}
    parts["breakdown"] = breakdown_intervals(ev, result.r_star, parts["breakdown"], of_reference=not on_hard,
                                             seed=problem.seed, recorded=problem.traffic.scenes is not None)
    out = Result(
        sensor=problem.sensor_kind, params=dict(problem.params), units={name: spec.unit},
        r_star={name: float(result.r_star)}, E_hard_star=ev.e_hard(result.r_star),
        E_soft_star=float(result.E_soft_star), solve=result,
        programs_run={"solve": solve_counts, "figures": figure_counts, "intervals": interval_counts},
        wall_s={"compile": clock.compile_s, "run": clock.run_s, "programs_compiled": clock.compiled,
                "programs_lowered": clock.lowered},
        scenarios=tuple(E.scenario_names),
        config=problem_config(problem), curves=curves, dense_check=dense, near_optimal=near,
        flags=tuple(answer["flags"]), domain=domain, reference=report.reference_summary(ev, problem, result.r_star, on_hard),
        judged=fresh, intervals=ci, **parts)
    return out, E
