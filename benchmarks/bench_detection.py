"""Detection as a physical probability: the smooth estimators against the reference E_ref.

    nice -n 15 python benchmarks/bench_detection.py [--sensor radar|camera|suite] [--law-config PATH]
        [--scenarios sc01] [--variants 1] [--points 10,20,30,45,60,90] [--draws 32]
        [--mc-samples 8] [--grid LO:HI:STEP ...] [--solve LO:HI ...] [--main-job] [--json PATH]

On the objective of the default problem with the sensor's probabilistic detection law (the
TOML at --law-config; default configs/sensors/laws/<sensor>_*.toml), at each HFOV point:

    E_ref        the hard objective's expectation over --draws Bernoulli draws per (frame,
                 vehicle), with its Monte-Carlo standard error (`Objective.reference`)
    E_hard       each detection decided by its probability's median (p >= 1/2)
    mean-field   one pass on expected histories
    relaxed-reference  E_ref's own draws, relaxed (the default under a probabilistic law for
                 several parameters; for one, straight-through: E_ref's value, this gradient)
    mc           --mc-samples relaxed-Bernoulli samples (temperature 0.5); 0 skips it

and each estimator's bias E - E_ref, also in units of E_ref's standard error. --grid compares
mean-field and relaxed-reference with E_ref on a grid: the largest relative gap and the argmins.
--seeds S,... gives each estimator's bias and its spread over seeds at --points.
--temperature-points P,... gives relaxed-reference's gap to E_ref at each of --temperatures.
--solve LO:HI runs the default solve and scipy's bounded Brent on E_ref over an interval, each
judged against the best point of a 1-deg grid of E_ref. --main-job also
runs `diffsense.optimise` on the default problem (every scenario, 8 variants, HFOV 30-180 deg)
with the shipped threshold law and with the probabilistic one, and reports r*, E_hard(r*) and
E_ref(r*): what switching the law would change in the quoted results.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
LAWS = {"radar": ROOT / "configs/sensors/laws/radar_swerling1.toml",
        "camera": ROOT / "configs/sensors/laws/camera_confidence.toml"}
# --sensor suite: the radar and the camera, each under its law above, fused; r is the radar's HFOV
# (the camera keeps its default), and the reference draws each member on its own.
SUITE_PARAM = "radar.hfov_deg"


def _param(args) -> str:
    return SUITE_PARAM if args.sensor == "suite" else "hfov_deg"


def _law(args) -> str | None:
    """The law TOML of --sensor (None for the suite, whose members take theirs from LAWS)."""
    if args.sensor == "suite":
        if args.law_config:
            raise SystemExit("error: --law-config applies to one sensor; the suite's members use " +
                             ", ".join(str(v) for v in LAWS.values()))
        return None
    return str(args.law_config or LAWS[args.sensor])


def _problem(args, law_config, **changes):
    import diffsense as ds
    from diffsense.metrics import EstimatorConfig

    estimator = changes.pop("estimator", EstimatorConfig(kind="mean-field", reference_draws=args.draws))
    fields = dict(sensor=args.sensor, scenarios=args.scenarios.split(","), variants=args.variants,
                  sensor_config=law_config, estimator=estimator)
    if args.sensor == "suite":
        from diffsense.sensors import Camera, Radar

        members = (Radar.from_toml(LAWS["radar"]), Camera.from_toml(LAWS["camera"]))
        fields |= dict(sensor=members, sensor_config=None, params={SUITE_PARAM: (1.0, 180.0)})
    return ds.Problem(**(fields | changes))


def estimator_table(args) -> list[dict]:
    """E_ref, E_hard and each estimator's E at every point of --points."""
    import diffsense as ds
    from diffsense.metrics import EstimatorConfig
    from diffsense.solve import Evaluator

    if not args.points:
        return []
    law = _law(args)
    ev = Evaluator(ds.objective(_problem(args, law)))
    rr = Evaluator(ds.objective(_problem(args, law, estimator=EstimatorConfig(reference_draws=args.draws))))
    mc = None
    if args.mc_samples:
        mc_est = EstimatorConfig(kind="mc", samples=args.mc_samples, reference_draws=args.draws)
        mc = Evaluator(ds.objective(_problem(args, law, estimator=mc_est)))
    rows = []
    for r in [float(v) for v in args.points.split(",")]:
        t0 = time.perf_counter()
        ref = ev.reference(r)
        row = {"r": r, "E_ref": float(ref.e), "E_ref_se": float(ref.e_se), "E_hard": ev.e_hard(r),
               "E_mean_field": float(np.sqrt(max(ev.e2_soft(r), 0.0))),
               "E_relaxed_reference": float(np.sqrt(max(rr.e2_soft(r), 0.0)))}
        if mc is not None:
            row["E_mc"] = float(np.sqrt(max(mc.e2_soft(r), 0.0)))
        for name in ("E_hard", "E_mean_field", "E_relaxed_reference", "E_mc"):
            if name in row:
                row[f"bias_{name[2:]}"] = row[name] - row["E_ref"]
        row["wall_s"] = time.perf_counter() - t0
        rows.append(row)
        print(_format(row), flush=True)
    return rows


def grid_agreement(args) -> list[dict]:
    """Each smooth estimator against E_ref on each --grid LO:HI:STEP: the largest relative gap
    and the distance between the argmins."""
    import diffsense as ds
    from diffsense.metrics import EstimatorConfig
    from diffsense.solve import Evaluator

    law = _law(args)
    ev = Evaluator(ds.objective(_problem(args, law)))
    smooth = {kind: Evaluator(ds.objective(_problem(args, law, estimator=EstimatorConfig(kind=kind, reference_draws=args.draws))))
              for kind in ("mean-field", "relaxed-reference")}
    out = []
    for text in args.grid:
        lo, hi, step = (float(v) for v in text.split(":"))
        r = np.arange(lo, hi + 0.5 * step, step)
        ref = np.array([ev.e_reference(x) for x in r])
        se = np.array([float(ev.reference(x).e_se) for x in r])
        row = {"grid": text, "points": int(r.size), "argmin_ref": float(r[ref.argmin()]),
               "E_ref_min": float(ref.min()), "E_ref_min_se": float(se[ref.argmin()]),
               "r": r.tolist(), "E_ref": ref.tolist(), "E_ref_se": se.tolist()}
        for kind, sev in smooth.items():
            e = np.array([np.sqrt(max(sev.e2_soft(x), 0.0)) for x in r])
            gap = np.abs(e - ref) / ref
            row[kind] = {"max_rel_gap": float(gap.max()), "r_max_gap": float(r[gap.argmax()]),
                         "gap_in_se_at_max": float(abs(e - ref)[gap.argmax()] / se[gap.argmax()]) if se[gap.argmax()] > 0 else None,
                         "argmin": float(r[e.argmin()]), "E_ref_at_argmin": float(ref[e.argmin()]), "E": e.tolist()}
        print(json.dumps({k: ({kk: vv for kk, vv in v.items() if kk != "E"} if isinstance(v, dict) else v)
                          for k, v in row.items() if not isinstance(v, list)}), flush=True)
        out.append(row)
    return out


def seed_spread(args) -> list[dict]:
    """Each estimator's bias and spread over --seeds (each seed redraws the measurement noise, the
    reference's uniforms and mc's) at every --points HFOV: per seed E_ref ± SE and each estimator's
    E; over seeds the mean and standard deviation of E_estimator - E_ref (paired: the same seed's
    noise) and of E_estimator itself."""
    import diffsense as ds
    from diffsense.metrics import EstimatorConfig
    from diffsense.solve import Evaluator

    law = _law(args)
    points = [float(v) for v in args.points.split(",")]
    kinds = ("mean-field", "relaxed-reference", "mc")
    per_seed = {r: [] for r in points}
    for seed in [int(v) for v in args.seeds.split(",")]:
        evs = {k: Evaluator(ds.objective(_problem(args, law, seed=seed, estimator=EstimatorConfig(
            kind=k, samples=args.mc_samples or 8, reference_draws=args.draws)))) for k in kinds}
        for r in points:
            ref = evs["mean-field"].reference(r)
            row = {"seed": seed, "E_ref": float(ref.e), "E_ref_se": float(ref.e_se)}
            row |= {k: float(np.sqrt(max(evs[k].e2_soft(r), 0.0))) for k in kinds}
            per_seed[r].append(row)
            print(json.dumps({"r": r} | row), flush=True)
    out = []
    for r, rows in per_seed.items():
        ref = np.array([x["E_ref"] for x in rows])
        summary = {"r": r, "seeds": len(rows), "E_ref_mean": float(ref.mean()), "E_ref_sd": float(ref.std(ddof=1)),
                   "E_ref_se_mean": float(np.mean([x["E_ref_se"] for x in rows]))}
        for k in kinds:
            e = np.array([x[k] for x in rows])
            summary[k] = {"bias_mean": float((e - ref).mean()), "bias_sd": float((e - ref).std(ddof=1)),
                          "rel_bias_mean": float((e / ref - 1).mean()), "E_sd": float(e.std(ddof=1))}
        print(json.dumps(summary), flush=True)
        out.append(summary | {"per_seed": rows})
    return out


def temperature_sweep(args) -> list[dict]:
    """relaxed-reference's gap to E_ref at each --temperature-points HFOV for each temperature of
    --temperatures [logit units]: the bias the relaxation trades for a gradient."""
    import diffsense as ds
    from diffsense.metrics import EstimatorConfig
    from diffsense.solve import Evaluator

    law = _law(args)
    unit = EstimatorConfig(kind="relaxed-reference", reference_draws=args.draws, reference_temperature=1.0)
    ev = Evaluator(ds.objective(_problem(args, law, estimator=unit)))  # tau is then the temperature
    out = []
    for r in [float(v) for v in args.temperature_points.split(",")]:
        ref = ev.reference(r)
        gaps = {t: float(np.sqrt(max(ev.e2_soft(r, t), 0.0)) / float(ref.e) - 1.0)
                for t in [float(v) for v in args.temperatures.split(",")]}
        row = {"r": r, "E_ref": float(ref.e), "E_ref_se": float(ref.e_se), "rel_gap": gaps}
        print(json.dumps(row), flush=True)
        out.append(row)
    return out


def brent_on_reference(E, lo: float, hi: float, best: float) -> dict:
    """scipy's bounded Brent on E_ref over [lo, hi] (`xatol` 1e-3 of the interval, as the solve's):
    a fresh evaluator, every evaluation counted; its final E_ref and the first evaluation count
    from which the best point so far is within 0.1 % of `best` (a grid's best E_ref [m])."""
    from diffsense.solve import Evaluator
    from scipy.optimize import minimize_scalar

    ev, trace = Evaluator(E), []

    def f(x):
        trace.append(ev.e_reference(float(x)))
        return trace[-1]

    t0 = time.perf_counter()
    minimize_scalar(f, bounds=(lo, hi), method="bounded", options={"xatol": 1e-3 * (hi - lo), "maxiter": 100})
    running = np.minimum.accumulate(trace)
    reached = np.nonzero(running <= best * 1.001)[0]
    return {"brent_evaluations": len(trace), "brent_E_ref": float(running[-1]),
            "brent_evaluations_to_0.1pct": int(reached[0]) + 1 if reached.size else None,
            "brent_wall_s": time.perf_counter() - t0}


def solve_against_brent(args) -> list[dict]:
    """The default solve (`diffsense.optimise`, default estimator) against bounded Brent on E_ref
    on each --solve LO:HI: E_ref at each answer with its standard error, against the best point
    of a 1-deg grid of E_ref, and the evaluations each needed."""
    import diffsense as ds
    from diffsense.metrics import EstimatorConfig
    from diffsense.solve import Evaluator

    law = _law(args)
    out = []
    for text in args.solve:
        lo, hi = (float(v) for v in text.split(":"))
        problem = _problem(args, law, params={_param(args): (lo, hi)}, estimator=EstimatorConfig(reference_draws=args.draws))
        E = ds.objective(problem)
        ev = Evaluator(E)
        grid = np.arange(lo, hi + 0.5, 1.0)
        dense = np.array([ev.e_reference(x) for x in grid])
        best = float(dense.min())
        t0 = time.perf_counter()
        result = ds.optimise(problem, E=E, figures=False)
        solve_s = time.perf_counter() - t0
        ref = result.reference
        r_star = next(iter(result.r_star.values()))
        evals = result.evaluations
        row = {"interval": text, "grid_best_r": float(grid[dense.argmin()]), "grid_best_E_ref": best,
               "r_star": r_star, "E_ref_star": ref["E_ref_star"], "E_ref_star_se": ref["E_ref_star_se"],
               "rel_to_grid_best": ref["E_ref_star"] / best - 1.0,
               "solve_sweep_steps": len(result.sweep), "solve_objective": evals["objective"],
               "solve_gradient": evals["gradient"], "solve_wall_s": solve_s} | brent_on_reference(E, lo, hi, best)
        print(json.dumps(row), flush=True)
        out.append(row)
    return out


def _format(row: dict) -> str:
    se = row["E_ref_se"]
    parts = [f"r {row['r']:7.2f}", f"E_ref {row['E_ref']:.4f} +- {se:.4f}"]
    for name in ("hard", "mean_field", "relaxed_reference", "mc"):
        if f"bias_{name}" in row:
            bias = row[f"bias_{name}"]
            parts.append(f"{name} {row['E_' + name]:.4f} ({bias:+.4f} m, {bias / se if se > 0 else float('nan'):+.1f} SE)")
    return " | ".join(parts)


def main_job(args) -> list[dict]:
    """The default main job with the shipped threshold law and with the probabilistic one."""
    import diffsense as ds
    from diffsense.solve import Evaluator

    out = []
    for law in (None, _law(args)):
        problem = ds.Problem(sensor=args.sensor, sensor_config=law)
        problem = problem.replace(estimator=dataclasses.replace(problem.question.estimator, reference_draws=args.draws))
        t0 = time.perf_counter()
        E = ds.objective(problem)
        result = ds.optimise(problem, E=E, figures=False)
        r_star = next(iter(result.r_star.values()))
        ref = Evaluator(E).reference(r_star)
        row = {"law": law or "threshold (shipped)", "r_star": r_star, "E_hard_star": result.E_hard_star,
               "E_ref_star": float(ref.e), "E_ref_star_se": float(ref.e_se), "wall_s": time.perf_counter() - t0}
        print(json.dumps(row), flush=True)
        out.append(row)
    return out


def problem_args(p: argparse.ArgumentParser) -> None:
    """The problem's options (sensor, law, scenarios, variants, reference draws), shared with
    bench_relaxation.py."""
    p.add_argument("--sensor", default="radar", choices=[*sorted(LAWS), "suite"],
                   help="suite: radar + camera under their laws, r the radar's HFOV")
    p.add_argument("--law-config", type=Path, help="sensor TOML with the probabilistic [detection] law")
    p.add_argument("--scenarios", default="sc01")
    p.add_argument("--variants", type=int, default=1)
    p.add_argument("--draws", type=int, default=32)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    problem_args(p)
    p.add_argument("--points", default="10,20,30,45,60,90", help="HFOV points [deg]; '' for none")
    p.add_argument("--mc-samples", type=int, default=8)
    p.add_argument("--grid", action="append", default=[], metavar="LO:HI:STEP",
                   help="also compare mean-field with E_ref on this HFOV grid [deg] (repeatable)")
    p.add_argument("--seeds", default="", help="seeds of the spread study at --points (e.g. 0,1,2,3,4); '' for none")
    p.add_argument("--temperature-points", default="", help="HFOV points [deg] of the temperature sweep; '' for none")
    p.add_argument("--temperatures", default="0.1,0.03,0.01,0.001,0.0001,0.00001",
                   help="relaxed-reference temperatures [logit units] of the temperature sweep")
    p.add_argument("--solve", action="append", default=[], metavar="LO:HI",
                   help="also run the default solve and bounded Brent on E_ref over this HFOV interval [deg] (repeatable)")
    p.add_argument("--main-job", action="store_true")
    p.add_argument("--json", type=Path)
    args = p.parse_args()
    if args.sensor == "suite" and args.main_job:
        p.error("--main-job runs one sensor (the main job's radar or camera), not the suite")
    report = {"args": {k: str(v) for k, v in vars(args).items()}, "table": estimator_table(args)}
    if args.grid:
        report["grid"] = grid_agreement(args)
    if args.seeds:
        report["seeds"] = seed_spread(args)
    if args.temperature_points:
        report["temperatures"] = temperature_sweep(args)
    if args.solve:
        report["solve"] = solve_against_brent(args)
    if args.main_job:
        report["main_job"] = main_job(args)
    if args.json:
        args.json.write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
