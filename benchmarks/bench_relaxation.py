"""The relaxed-reference (or straight-through) temperature against issue #13's targets, over seeds.

    nice -n 10 python benchmarks/bench_relaxation.py [--sensor radar] [--grid LO:HI:STEP ...]
        [--temperatures 0.01,0.003,0.001,0.0001] [--seeds 0] [--solve LO:HI ...]
        [--solve-temperatures 0.01,0.001] [--tau-schedule 4,2,1]
        [--estimator relaxed-reference|straight-through] [--judge-draws M [--judge-grid]] [--brent]
        [--cost-at HFOV --repeats 15] [--json PATH]

For each seed (scene variants, measurement noise and the reference's uniforms), on the problem of
`bench_detection.py` (sc01, 1 variant, the sensor's probabilistic law, K = --draws):

- agreement: on each --grid, E_ref at every point and relaxed-reference at every temperature
  lambda of --temperatures (one compiled program: reference_temperature 1, the temperature given
  as tau); the largest relative gap |E - E_ref| / E_ref, where, in E_ref's standard errors, and
  the distance between the argmins. At the point of the largest gap, the smallest margin
  |logit p - logit u| over every (draw, frame, vehicle) and how many margins are below lambda:
  the draws near flipping, which a relaxation of width lambda leaves part-detected.
- solve: on each --solve LO:HI, `diffsense.optimise` with relaxed-reference at each lambda of
  --solve-temperatures (its default continuation 4, 2, 1 times lambda; the answer judged on
  E_ref), E_ref(r*) against the best point of the 1-deg grid of E_ref on LO:HI (taken from an
  agreement grid LO:HI:1 when there is one) and the evaluations it used; and its search counted
  as Brent's is: every program in order, and the first count from which the best E_ref seen is
  within 0.1 % of the grid's best (`search_trace`).
- judge (--judge-draws M): each solve's answer r* and the grid's best r_b on E_ref's own K draws
  and on M fresh draws of the same scene (indices K ... K+M-1, independent of the draws both were
  chosen on), with the paired difference E(r*) / E(r_b) - 1 and its standard error (the delta
  method on the draws' paired differences); with --judge-grid also the whole 1-deg grid on the
  fresh draws, its best, and r* against it. With --brent, bounded Brent on E_ref over the
  interval too (`bench_detection.py`'s: evaluations, final E_ref, evaluations to within 0.1 %).
- cost (--cost-at HFOV, instead of the above): the median time of one E_ref, and of each
  estimator's value and value and gradient, over --repeats interleaved rounds.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np
from bench_detection import _law, _param, _problem, brent_on_reference, problem_args


def _ref_grid(ev, r):
    ref = [ev.reference(x) for x in r]
    return np.array([float(x.e) for x in ref]), np.array([float(x.e_se) for x in ref])


def _margins(E, r_deg, draws, lam):
    """The smallest |logit p - logit u| over the reference's draws at r, and how many are below lam."""
    import equinox as eqx
    import jax.numpy as jnp

    from diffsense.metrics import reference_draw_margins

    m = np.asarray(eqx.filter_jit(reference_draw_margins)(E, jnp.asarray(r_deg), draws))
    return float(m.min()), int(np.sum(m < lam))


def agreement(args, seed) -> list[dict]:
    import diffsense as ds
    from diffsense.metrics import EstimatorConfig
    from diffsense.solve import Evaluator

    unit = EstimatorConfig(kind=args.estimator, reference_draws=args.draws, reference_temperature=1.0)
    E = ds.objective(_problem(args, args.law, seed=seed, estimator=unit))
    ev = Evaluator(E)
    out = []
    for text in args.grid:
        lo, hi, step = (float(v) for v in text.split(":"))
        r = np.arange(lo, hi + 0.5 * step, step)
        ref, se = _ref_grid(ev, r)
        row = {"seed": seed, "grid": text, "argmin_ref": float(r[ref.argmin()]), "E_ref": ref.tolist(),
               "E_ref_se": se.tolist(), "r": r.tolist(), "by_temperature": {}}
        for lam in args.temperatures:
            e = np.array([np.sqrt(max(ev.e2_soft(x, lam), 0.0)) for x in r])
            gap = np.abs(e - ref) / ref
            i = int(gap.argmax())
            smallest, below = _margins(E, r[i], args.draws, lam)
            row["by_temperature"][str(lam)] = {
                "max_rel_gap": float(gap.max()), "r_max_gap": float(r[i]),
                "gap_in_se": float(abs(e - ref)[i] / se[i]) if se[i] > 0 else None,
                "points_over_1pct": int(np.sum(gap > 0.01)), "argmin": float(r[e.argmin()]),
                "argmin_distance": float(abs(r[e.argmin()] - r[ref.argmin()])),
                "smallest_margin_at_max_gap": smallest, "margins_below_lambda_at_max_gap": below, "E": e.tolist()}
            brief = {k: v for k, v in row["by_temperature"][str(lam)].items() if k != "E"}
            print(json.dumps({"seed": seed, "grid": text, "lambda": lam} | brief), flush=True)
        out.append(row)
    return out


def _paired(a, b) -> dict:
    """E(a) / E(b) - 1 from two points' per-draw hard objectives [m^2] on the same draws, with its
    standard error: that of the paired differences' mean, over 2 E(b)^2 (delta method, near 0)."""
    a, b = np.asarray(a.draws, np.float64), np.asarray(b.draws, np.float64)
    d = a - b
    return {"rel": float(np.sqrt(a.mean() / b.mean()) - 1.0),
            "rel_se": float(d.std(ddof=1) / np.sqrt(d.size) / (2.0 * b.mean()))}


def judge(args, objective, r_star: float, grid: dict) -> dict:
    """r* and the grid's best r_b on E_ref's own K draws and on --judge-draws fresh ones."""
    import equinox as eqx
    import jax.numpy as jnp

    on = eqx.filter_jit(lambda o, x, ids: o.reference(o.point(x), draws=ids))
    own, fresh = jnp.arange(args.draws), jnp.arange(args.draws, args.draws + args.judge_draws)
    r_best = float(grid["r"][int(np.argmin(grid["E_ref"]))])
    at = {x: (on(objective, jnp.asarray(x), own), on(objective, jnp.asarray(x), fresh)) for x in (r_star, r_best)}
    row = {"r_best": r_best, "fresh_draws": args.judge_draws,
           "own": _paired(at[r_star][0], at[r_best][0]), "fresh": _paired(at[r_star][1], at[r_best][1]),
           "E_fresh_star": float(at[r_star][1].e), "E_fresh_star_se": float(at[r_star][1].e_se),
           "E_fresh_best": float(at[r_best][1].e), "E_fresh_best_se": float(at[r_best][1].e_se)}
    if args.judge_grid:
        refs = [on(objective, jnp.asarray(x), fresh) for x in grid["r"]]
        i = int(np.argmin([float(v.e) for v in refs]))
        row |= {"fresh_grid_best_r": float(grid["r"][i]), "fresh_grid_best_E": float(refs[i].e),
                "fresh_vs_fresh_grid_best": _paired(at[r_star][1], refs[i])}
    return row


def solves(args, seed, grids) -> list[dict]:
    import diffsense as ds
    from diffsense.metrics import EstimatorConfig
    from diffsense.solve import Evaluator

    out = []
    for text in args.solve:
        lo, hi = (float(v) for v in text.split(":"))
        known = next((g for g in grids if g["grid"] == f"{text}:1"), None)
        if known is None:
            ev = Evaluator(ds.objective(_problem(args, args.law, seed=seed)))
            r = np.arange(lo, hi + 0.5, 1.0)
            known = {"r": r.tolist(), "E_ref": _ref_grid(ev, r)[0].tolist()}
        best = float(min(known["E_ref"]))
        for lam in args.solve_temperatures:
            est = EstimatorConfig(kind=args.estimator, reference_draws=args.draws, reference_temperature=lam)
            problem = _problem(args, args.law, seed=seed, params={_param(args): (lo, hi)}, estimator=est)
            if args.tau_schedule:
                schedule = tuple(float(v) for v in args.tau_schedule.split(","))
                problem = problem.replace(solve=dataclasses.replace(problem.solver.solve, tau_schedule=schedule))
            t0 = time.perf_counter()
            events = []
            result = ds.optimise(problem, figures=False, on_evaluation=events.append)
            ref = result.reference
            row = {"seed": seed, "interval": text, "estimator": args.estimator, "lambda": lam, "tau_schedule": list(problem.solver.solve.tau_schedule),
                   "grid_best_E_ref": best,
                   "r_star": next(iter(result.r_star.values())), "E_ref_star": ref["E_ref_star"],
                   "E_ref_star_se": ref["E_ref_star_se"], "rel_to_grid_best": ref["E_ref_star"] / best - 1.0,
                   "sweep_steps": len(result.sweep), "objective": result.evaluations["objective"],
                   "gradient": result.evaluations["gradient"], "notes": list(result.notes),
                   "wall_s": time.perf_counter() - t0} | search_trace(events, ref["estimator_used"], best)
            E = ds.objective(problem) if args.judge_draws or args.brent else None  # built once for both
            if args.judge_draws:
                row["judge"] = judge(args, E, row["r_star"], known)
            if args.brent:
                row["brent"] = brent_on_reference(E, lo, hi, best)
            print(json.dumps(row), flush=True)
            out.append(row)
    return out


def search_trace(events: list[dict], estimator_used: str, best: float) -> dict:
    """The solve's search counted as Brent's is (`brent_on_reference`): every program it ran in
    order (E_ref values and value-and-gradients, sweep included; the hard evaluations reported
    after the answer left out), and the first count from which the best E_ref seen so far is
    within 0.1 % of `best` [m]. A value-and-gradient's value is E_ref only under straight-through;
    under another estimator it counts as a program but not as a value seen."""
    search = [e for e in events if e["kind"] in ("reference", "soft")]
    seen = [e["E_m"] if e["kind"] == "reference" or estimator_used == "straight-through" else np.inf
            for e in search]
    running = np.minimum.accumulate(seen) if seen else np.array([])
    reached = np.nonzero(running <= best * 1.001)[0]
    first = int(reached[0]) + 1 if reached.size else None
    return {"search_programs": len(search), "search_value_and_grads": sum(e["kind"] == "soft" for e in search),
            "programs_to_0.1pct": first,
            "value_and_grads_to_0.1pct": sum(e["kind"] == "soft" for e in search[:first]) if first else None}


def cost(args) -> list[dict]:
    """Wall time of one evaluation at --cost-at of E_ref, and of each estimator's value and value
    and gradient: compiled once, then --repeats rounds, each calling every program once in a
    shuffled order; medians."""
    import os
    import random
    import statistics

    import equinox as eqx
    import jax
    import jax.numpy as jnp

    import diffsense as ds
    from diffsense.metrics import EstimatorConfig

    name = _param(args)
    objs = {k: ds.objective(_problem(args, args.law, estimator=EstimatorConfig(kind=k, reference_draws=args.draws)))
            for k in ("relaxed-reference", "straight-through")}
    value = eqx.filter_jit(lambda o, r: o.e2({name: r}))
    vg = eqx.filter_jit(lambda o, r: jax.value_and_grad(lambda x: o.e2({name: x}))(r))
    ref = eqx.filter_jit(lambda o, r: o.reference({name: r}).e2)
    r = jnp.asarray(args.cost_at)
    programs = {"E_ref": lambda: ref(objs["relaxed-reference"], r)}
    for k, o in objs.items():
        programs[f"{k} value"] = lambda o=o: value(o, r)
        programs[f"{k} value+grad"] = lambda o=o: vg(o, r)
    for f in programs.values():
        jax.block_until_ready(f())
    times = {k: [] for k in programs}
    order = list(programs)
    for _ in range(args.repeats):
        random.shuffle(order)
        for k in order:
            t0 = time.perf_counter()
            jax.block_until_ready(programs[k]())
            times[k].append(time.perf_counter() - t0)
    print(f"load average (1, 5, 15 min) after the rounds: {os.getloadavg()}")
    print(f"| program (HFOV {args.cost_at:g} deg, K = {args.draws}) | median [ms] | / E_ref |\n|---|---|---|")
    base = statistics.median(times["E_ref"])
    rows = []
    for k, v in times.items():
        m = statistics.median(v)
        rows.append({"program": k, "median_s": m, "ratio_to_E_ref": m / base})
        print(f"| {k} | {1e3 * m:.1f} | {m / base:.2f} |")
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    problem_args(p)
    p.add_argument("--grid", action="append", default=[], metavar="LO:HI:STEP", help="agreement grid [deg] (repeatable)")
    p.add_argument("--temperatures", default="0.01,0.003,0.001,0.0001", help="lambda [logit units] of the agreement grids")
    p.add_argument("--seeds", default="0")
    p.add_argument("--solve", action="append", default=[], metavar="LO:HI", help="solve interval [deg] (repeatable)")
    p.add_argument("--solve-temperatures", default="0.01", help="lambda [logit units] of the solves; '' for none")
    p.add_argument("--tau-schedule", default="",
                   help="the solves' continuation, multipliers of lambda, largest first (default: the config's)")
    p.add_argument("--estimator", default="relaxed-reference", choices=("relaxed-reference", "straight-through"),
                   help="the estimator of the grids and solves (straight-through: E_ref forward, relaxed backward)")
    p.add_argument("--judge-draws", type=int, default=0, metavar="M",
                   help="judge each solve's answer and the grid's best on M fresh draws (0: not)")
    p.add_argument("--judge-grid", action="store_true", help="with --judge-draws: the whole 1-deg grid on the fresh draws too")
    p.add_argument("--brent", action="store_true", help="also run bounded Brent on E_ref over each --solve interval")
    p.add_argument("--cost-at", type=float, metavar="HFOV",
                   help="time E_ref and each estimator's value and value-and-gradient at this HFOV [deg] instead")
    p.add_argument("--repeats", type=int, default=15, help="rounds of --cost-at")
    p.add_argument("--json", type=Path)
    args = p.parse_args()
    args.law = _law(args)
    args.temperatures = [float(v) for v in args.temperatures.split(",") if v]
    args.solve_temperatures = [float(v) for v in args.solve_temperatures.split(",") if v]
    report = {"args": {k: str(v) for k, v in vars(args).items()}, "agreement": [], "solve": []}
    if args.cost_at is not None:
        report["cost"] = cost(args)
        if args.json:
            args.json.write_text(json.dumps(report, indent=1))
        return
    for seed in [int(v) for v in args.seeds.split(",")]:
        grids = agreement(args, seed)
        report["agreement"] += grids
        report["solve"] += solves(args, seed, grids)
        if args.json:  # written after every seed: a stopped run keeps what it finished
            args.json.write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
