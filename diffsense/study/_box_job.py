"""The many-parameter main job: one box solve of J = E + lambda * cost (`optimise_box`), and the
E-versus-cost front by a warm-started sweep of lambda (`pareto`).

    front = ds.pareto(ds.Problem.from_suite("configs/suites/radar_camera_d4.toml"))
    front.front()            # the non-dominated designs, cheapest first

Each lambda's box solve starts from the coarse sample and from the previous lambda's answer
(warm start); evaluations are memoised across the sweep, so the sample is paid for once.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from diffsense.metrics import (
    Objective,
    estimable,
    is_deterministic,
    load_costs,
    make_cost,
    member_costs,
)
from diffsense.runtime import CompileClock, InputError
from diffsense.solve import BoxFunctions, BoxResult, Evaluator, box_solve, pareto_sweep
from diffsense.study._domain import domain_check, domain_note
from diffsense.study._intervals import box_intervals, breakdown_intervals, strata
from diffsense.study._judge import judged
from diffsense.study._line_report import reference_summary
from diffsense.study._objective import objective, scenes_line
from diffsense.study._problem import Problem, problem_config
from diffsense.study._r_star import AXIS_POINTS, REFINE_POINTS, REFINE_ROUNDS
from diffsense.study._result import Result

# The cost weights a front is traced at by default [m per currency unit]: from E alone (0) to
# 0.05 m per EUR, where the shipped sensors' price range (their defaults cost 132 EUR together)
# outweighs metres of E; roughly doubling, so that the front's knee is bracketed.
DEFAULT_LAMBDAS: tuple[float, ...] = (0.0, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05)

Say = Callable[[str], None]
OnEvaluation = Callable[[dict], None] | None


def _functions(problem: Problem, E: Objective, on_evaluation: OnEvaluation, solves: int = 1, intervals: bool = True):
    """The Evaluator, the box functions (cost model included) and the clipped default start."""
    ev = Evaluator(E)
    # Under a probabilistic detection law answers are judged on E_ref, the expectation the
    # estimator approximates (as the one-parameter solve does); under the threshold law it is E_hard.
    e_answer = None if _on_hard(problem, E) else ev.e_reference
    # ... and the starts are screened on E_ref's first few draws: a cheaper value of the same
    # estimator (no cheaper fidelity exists where E_hard is the answer)
    screen = None if _on_hard(problem, E) else min(problem.solver.box.screen_draws, E.estimator.reference_draws)
    fns = BoxFunctions.from_evaluator(ev, cost=make_cost(load_costs(problem.question.costs), E.sensor),
                                      e_answer=e_answer, screen_draws=screen)
    axes = (intervals and problem.solver.box.r_star_axes  # r*'s interval is made
            and estimable(*strata(ev, problem.traffic.scenes is not None)))
    planned = _planned(problem, screen is not None, solves, axes)
    if on_evaluation is not None:
        def listen(event) -> None:  # what a progress display shows: E, the cost there, the count
            done = sum(fns.counts.values())
            on_evaluation({"kind": event.kind, "E_m": event.value, "tau": event.tau, "cost": fns.cost(event.x)[0],
                           "done": done, "planned": max(planned, done)})

        fns.listener = listen
    defaults = E.sensor.defaults()
    start = [min(max(defaults[n], lo), hi) for n, (lo, hi) in problem.params.items()]
    return ev, fns, start


def _on_hard(problem: Problem, E: Objective) -> bool:
    """Whether answers are judged on E_hard (the threshold law, or the hard estimator) or on E_ref."""
    return problem.question.estimator.kind == "hard" or is_deterministic(E.sensor)


def _units(problem: Problem) -> dict[str, str]:
    return {n: s.unit for n, s in problem.sensing.specs.items()}


def _member_costs(problem: Problem, E: Objective, r: dict[str, float]) -> dict[str, float]:
    """Each member's cost at r [currency], by member name (a lone sensor's under its kind)."""
    return member_costs(load_costs(problem.question.costs), E.sensor, r)


def _planned(problem: Problem, screening: bool, solves: int = 1, intervals: bool = True) -> int:
    """The evaluations a progress display expects: the soft budget, the hard sample or the
    screen with its best points, and r*'s interval along each axis."""
    box, d = problem.solver.box, len(problem.params)
    # r*'s interval (where the scenes give one): each axis's points and its refinement, at most
    axes = d * (AXIS_POINTS + REFINE_ROUNDS * REFINE_POINTS) if intervals else 0
    if screening and box.screen_points >= 0:
        return solves * box.max_soft + (box.screen_points or 8 * d + 8) + box.starts + axes
    return solves * box.max_soft + (box.samples or 2 * d + 2) + axes


def optimise_box(problem: Problem, E: Objective | None, predictor: Any, say: Say, on_evaluation: OnEvaluation,
                 judge: bool = True) -> Result:
    """Many parameters (or a cost): the box solve (`diffsense.solve.box_solve`): a coarse hard
    sample, BFGS with temperature continuation from its best points, every answer checked on the
    hard objective J = E_hard + cost_weight * cost."""
    with CompileClock() as clock:
        say(scenes_line(problem))
        E = objective(problem, predictor=predictor, progress=say) if E is None else E
        ev, fns, start = _functions(problem, E, on_evaluation)
        domain = domain_check(E, getattr(E.predictor, "validation_rmse_m", None))
        say(f"{problem.sensor_kind}: box solve of {', '.join(problem.params)}")
        config = dataclasses.replace(problem.solver.box, cost_weight=problem.question.cost_weight, seed=problem.seed)
        box = box_solve(fns, problem.params, config, extra_starts=[start])
        x = [box.x_star[n] for n in E.names]
        on_ref, recorded = not _on_hard(problem, E), problem.traffic.scenes is not None
        solve_counts = dict(ev.counts)
        star = breakdown_intervals(ev, x, ev.breakdown(x, of_reference=on_ref), of_reference=on_ref,
                                   seed=problem.seed, recorded=recorded)
        parts = {"breakdown": star, "tracked": star["tracked"]}
        ev.scene_sums(start, on_ref)  # the default suite the answer is compared with: counted in "figures"
        after = {k: ev.counts[k] - solve_counts[k] for k in ev.counts}
        weight, before = problem.question.cost_weight, {"hard": ev.counts["hard"], "reference": ev.reference_count}
        ci = box_intervals(ev, x, start, of_reference=on_ref, seed=problem.seed, recorded=recorded,
                           bounds=[problem.params[n] for n in E.names] if problem.solver.box.r_star_axes else None,
                           offset_at=lambda y: weight * fns.cost(y)[0])
        interval_counts = {"hard": ev.counts["hard"] - before["hard"], "reference": ev.reference_count - before["reference"]}
        fresh = None
        if judge:
            say(f"{problem.sensor_kind}: judging r* on fresh scenes and draws")
            fresh = judged(problem, E, box.x_star)
    notes = tuple(f"{n} is on its {side} bound" for n, side in box.on_bound.items() if side)
    if domain_note(domain):
        notes += (domain_note(domain),)
    return Result(
        sensor=problem.sensor_kind, params=dict(problem.params), units=_units(problem),
        r_star=dict(box.x_star), E_hard_star=ev.e_hard(x), E_soft_star=float(box.E_soft), solve=None, box=box,
        reference=reference_summary(ev, problem, x, _on_hard(problem, E)),
        programs_run={"solve": solve_counts, "figures": after, "intervals": interval_counts},
        wall_s={"compile": clock.compile_s, "run": clock.run_s, "programs_compiled": clock.compiled,
                "programs_lowered": clock.lowered},
        scenarios=tuple(E.scenario_names), config=problem_config(problem), domain=domain, box_notes=notes,
        judged=fresh, member_costs=_member_costs(problem, E, box.x_star), intervals=ci, **parts)


@dataclasses.dataclass(frozen=True)
class ParetoFront:
    """The E-versus-cost designs of a suite problem, one per cost weight lambda.

    Attributes:
        sensor: the suite's name ("radar+camera").
        units: each parameter's unit.
        currency: the cost model's currency.
        lambdas: the cost weights, in sweep order [m per currency unit].
        designs: each lambda's box solve (r*, E_hard, cost, dJ/dr and bounds at r*).
        on_front: whether each design is non-dominated in (E, cost) among the designs.
        cloud: (cost, E [m]) of every point the sweep evaluated on the hard objective.
        counts: distinct soft (value and gradient) and hard evaluations of the whole sweep.
        wall_s: the sweep's wall time [s], the objective's construction included.
        judged_on: which E the designs, the front and the cloud hold: "E_hard" (the threshold law,
            or the hard estimator), or "E_ref" (a probabilistic detection law: the expectation of
            the hard objective over detection draws, as the one-parameter solve judges).
        member_costs: each design's cost per member {name: cost} (a lone sensor's under its kind).
    """

    sensor: str
    units: dict[str, str]
    currency: str
    lambdas: tuple[float, ...]
    designs: tuple[BoxResult, ...]
    on_front: tuple[bool, ...]
    cloud: tuple[tuple[float, float], ...]
    counts: dict[str, int]
    wall_s: float
    judged_on: str = "E_hard"
    member_costs: tuple[dict[str, float], ...] | None = None

    def front(self) -> list[int]:
        """Indices of the non-dominated designs, cheapest first."""
        return sorted((i for i, f in enumerate(self.on_front) if f), key=lambda i: self.designs[i].cost)

    def to_dict(self) -> dict[str, Any]:
        """pareto.json's content: E [m] under the key `<judged_on>_m` ("E_hard_m" or "E_ref_m")."""
        key = f"{self.judged_on}_m"
        designs = [{"lambda": lam, "r_star": d.x_star, key: d.E_hard, "E_soft_m": d.E_soft, "cost": d.cost,
                    "J": d.J_star, "on_front": f, "on_bound": d.on_bound, "gradient": d.gradient, "source": d.source,
                    "evaluations": d.counts}
                   for lam, d, f in zip(self.lambdas, self.designs, self.on_front)]
        for design, costs in zip(designs, self.member_costs or ()):
            design["cost_by_member"] = costs
        return {"sensor": self.sensor, "judged_on": self.judged_on, "currency": self.currency, "units": self.units, "lambdas": list(self.lambdas),
                "designs": designs, "front": self.front(), "evaluations": self.counts, "wall_s": self.wall_s,
                "cloud": {"cost": [c for c, _ in self.cloud], key: [e for _, e in self.cloud]}}


def check_lambdas(lambdas: Sequence[float]) -> tuple[float, ...]:
    """The cost weights of a sweep, sorted ascending; InputError (one line) unless at least two,
    distinct, finite and >= 0."""
    values = tuple(float(v) for v in lambdas)
    if len(values) < 2 or not all(np.isfinite(v) and v >= 0 for v in values):
        raise InputError(f"a Pareto sweep needs at least two cost weights >= 0, got {list(lambdas)}")
    if len(set(values)) != len(values):
        raise InputError(f"cost weight {sorted(v for v in values if values.count(v) > 1)[0]:g} is given twice")
    return tuple(sorted(values))


def pareto(problem: Problem, lambdas: Sequence[float] = DEFAULT_LAMBDAS, *, E: Objective | None = None,
           predictor: Any = None, progress: Say | None = None, on_evaluation: OnEvaluation = None) -> ParetoFront:
    """The E-versus-cost front of `problem`: a box solve per cost weight in `lambdas` (sorted
    ascending; `problem.question.cost_weight` is not used), each warm-started from the previous answer.
    `E`, `predictor`, `progress` and `on_evaluation` as for `diffsense.optimise`; the events also
    carry "cost", the cost of the evaluated point."""
    lambdas = check_lambdas(lambdas)
    say = progress or (lambda message: None)
    t0 = time.perf_counter()
    say(scenes_line(problem))
    E = objective(problem, predictor=predictor, progress=say) if E is None else E
    ev, fns, start = _functions(problem, E, on_evaluation, len(lambdas), intervals=False)
    config = dataclasses.replace(problem.solver.box, seed=problem.seed)
    judged_on = "E_hard" if _on_hard(problem, E) else "E_ref"

    def solved(k: int, lam: float, result: BoxResult) -> None:
        say(f"{problem.sensor_kind}: lambda {lam:g} ({k + 1}/{len(lambdas)}): {judged_on} {result.E_hard:.4f} m, "
            f"cost {result.cost:.2f}, {result.counts['soft']} value-and-gradient + {result.counts['hard']} hard")

    designs, on_front = pareto_sweep(fns, problem.params, lambdas, config, extra_starts=[start], on_solved=solved)
    cloud = tuple((fns.cost(e.x)[0], e.value) for e in fns.history if e.kind == "hard")
    return ParetoFront(sensor=problem.sensor_kind, units=_units(problem),
                       currency=load_costs(problem.question.costs).currency, lambdas=lambdas, designs=designs,
                       on_front=on_front, cloud=cloud, counts=dict(fns.counts), wall_s=time.perf_counter() - t0,
                       judged_on=judged_on, member_costs=tuple(_member_costs(problem, E, d.x_star) for d in designs))
