"""What the one-parameter main job reports beside r*: the curves its figures draw, the
breakdowns, the dense reference check and the reference summary of result.json. Every figure is
read from the evaluator's memoised evaluations where it can be."""

from __future__ import annotations

import math
from typing import Any

import jax
import numpy as np

from diffsense.metrics import Objective
from diffsense.runtime import call, to_host
from diffsense.scene import ROLE_NAMES
from diffsense.solve import Evaluator, basin_check, dense_grid_search
from diffsense.study._problem import Problem
from diffsense.study._result import Curves


def first_variant(scenes):
    return jax.tree.map(lambda a: a[0], scenes)


def curves(ev: Evaluator, E: Objective, result, lo: float, hi: float, extra: int, hard_only: bool,
           soft_is_reference: bool = False) -> Curves:
    """What the figures draw. `soft_is_reference` (straight-through under a probabilistic law):
    E_soft's value is E_ref, read from the reference evaluations, and dE/dr is drawn where the
    solve evaluated it (NaN elsewhere): a value-and-gradient at every sweep step would cost the
    main job 2K predictor passes a step for the figure alone."""
    tau = result.tau_schedule[-1] if result.tau_schedule else 1.0
    solved = {x[0] for x in ev.soft_points(tau)} if soft_is_reference else set()
    r_curve = sorted({p.r for p in result.sweep} | {result.r_star} | solved
                     | {float(r) for r in (np.linspace(lo, hi, extra) if extra else [])})
    soft, grad, hard = [], [], []
    for r in r_curve:
        if hard_only:
            e2, g = ev.e_hard(r) ** 2, 0.0
        elif soft_is_reference and r not in solved:
            e2, g = ev.e_reference(r) ** 2, math.nan
        else:
            e2, g = ev.value_and_grad(r, tau)[0], ev.value_and_grad(r, tau)[1][0]
        e = math.sqrt(max(e2, 0.0))
        soft.append(e)
        grad.append(g / (2 * e) if e > 0 else 0.0)  # dE/dr = dE^2/dr / (2E)
        hard.append(ev.e_hard(r))
    gt, sensor = {}, {}
    for r in [p.r for p in result.sweep]:
        h = ev.hard(r)
        for i, name in enumerate(E.scenario_names):
            gt[name] = h.rmse_gt[i]
            sensor.setdefault(name, {})[r] = h.rmse_sensor[i]
    # a[0] on the device: in a multi-process run the whole array is not addressable here
    first = to_host(call(first_variant, E.data.scenes))  # nominal variant, first scenario
    cols = [v for v in range(1, first.present.size) if first.present[v]]  # the ego knows itself
    # From the hard evaluations (memoised: lo and hi are sweep steps), not a program of its own.
    timeline = {r: np.asarray(ev.hard(r).p_detect[0])[:, cols] for r in sorted({lo, result.r_star, hi})}
    return Curves(r=tuple(r_curve), E_soft=tuple(soft), E_hard=tuple(hard), dE_dr=tuple(grad),
                  horizon_gt=gt, horizon_sensor=sensor, horizon_s=E.spec.horizon_s(), timeline=timeline,
                  timeline_roles=tuple(ROLE_NAMES[int(first.role[v])] for v in cols), dt_s=float(first.dt_s))


def breakdowns(ev: Evaluator, result, on_hard: bool) -> dict[str, Any]:
    """The breakdown at r* and at every sweep step, and the tracked question's pieces at r*: of
    the value the answer is chosen on (E_hard, or E_ref over its detection draws)."""
    star = ev.breakdown(result.r_star, of_reference=not on_hard)
    return {"breakdown": star, "tracked": star["tracked"],
            "sweep_breakdown": tuple(ev.breakdown(p.r, of_reference=not on_hard) for p in result.sweep)}


def dense_check(ev: Evaluator, result, lo: float, hi: float, step: float) -> dict[str, Any]:
    """The reference E_ref (the hard objective's expectation over detection draws; E_hard itself
    under a deterministic detection law) on a dense grid, and whether r* lies in the basin of its
    best point."""
    dense = dense_grid_search(ev.e_reference, (lo, hi), step)
    star = ev.reference(result.r_star)
    why = basin_check(dense, result.r_star, float(star.e), result.bracket)
    i = dense.best_index
    best = ev.reference(float(dense.r[i]))
    return {
        "step": step, "evaluations": dense.evaluations, "wall_s": dense.wall_s, "objective": "reference",
        "reference_draws": int(best.draws.size),
        "r_best": float(dense.r[i]), "E_ref_best": float(best.e), "E_ref_best_se": float(best.e_se),
        "E_ref_star": float(star.e), "E_ref_star_se": float(star.e_se),
        "basin": list(dense.basin()), "in_basin": why is None,
        "E_ref_star_minus_best": float(star.e) - float(best.e),
        "verdict": why or f"r* lies in the basin {list(dense.basin())} of the best dense point "
                          f"r={float(dense.r[i]):.6g}",
    }


def reference_summary(ev: Evaluator, problem: Problem, r_star: float, on_hard: bool) -> dict[str, Any]:
    """result.json's "reference": E_ref at r* with its standard error, what the answer was judged
    on, and the estimator asked for and the one it stands for ("auto" resolved)."""
    ref = ev.reference(r_star)
    asked = problem.question.estimator.kind
    used = getattr(ev.objective, "estimator_kind", asked)
    return {"answer_on": "E_hard" if on_hard else "E_ref", "estimator": asked, "estimator_used": used,
            "E_ref_star": float(ref.e), "E_ref_star_se": float(ref.e_se), "draws": int(ref.draws.size)}
