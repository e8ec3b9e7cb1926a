"""Detection as a physical probability: the smooth estimators against the reference E_ref.

    nice -n 15 python benchmarks/bench_detection.py [--sensor radar] [--law-config PATH]
        [--scenarios sc01] [--variants 1] [--points 10,20,30,45,60,90] [--draws 32]
        [--mc-samples 8] [--grid LO:HI:STEP ...] [--main-job] [--json PATH]

On the objective of the default problem with the sensor's probabilistic detection law (the
TOML at --law-config; default configs/sensors/laws/<sensor>_*.toml), at each HFOV point:

    E_ref        the hard objective's expectation over --draws Bernoulli draws per (frame,
                 vehicle), with its Monte-Carlo standard error (`Objective.reference`)
    E_hard       each detection decided by its probability's median (p >= 1/2)
    mean-field   the default estimator: one pass on expected histories
    mc           --mc-samples relaxed-Bernoulli samples (temperature 0.5); 0 skips it

and each estimator's bias E - E_ref, also in units of E_ref's standard error. --grid compares the
mean-field estimator with E_ref on a grid: the largest relative gap and the two argmins. --main-job also
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


def _problem(args, law_config, **changes):
    import diffsense as ds
    from diffsense.metrics import EstimatorConfig

    estimator = changes.pop("estimator", EstimatorConfig(reference_draws=args.draws))
    fields = dict(sensor=args.sensor, scenarios=args.scenarios.split(","), variants=args.variants,
                  sensor_config=law_config, estimator=estimator)
    return ds.Problem(**(fields | changes))


def estimator_table(args) -> list[dict]:
    """E_ref, E_hard and each estimator's E at every point of --points."""
    import diffsense as ds
    from diffsense.metrics import EstimatorConfig
    from diffsense.solve import Evaluator

    if not args.points:
        return []
    law = str(args.law_config or LAWS[args.sensor])
    ev = Evaluator(ds.objective(_problem(args, law)))
    mc = None
    if args.mc_samples:
        mc_est = EstimatorConfig(kind="mc", samples=args.mc_samples, reference_draws=args.draws)
        mc = Evaluator(ds.objective(_problem(args, law, estimator=mc_est)))
    rows = []
    for r in [float(v) for v in args.points.split(",")]:
        t0 = time.perf_counter()
        ref = ev.reference(r)
        row = {"r": r, "E_ref": float(ref.e), "E_ref_se": float(ref.e_se), "E_hard": ev.e_hard(r),
               "E_mean_field": float(np.sqrt(max(ev.e2_soft(r), 0.0)))}
        if mc is not None:
            row["E_mc"] = float(np.sqrt(max(mc.e2_soft(r), 0.0)))
        for name in ("E_hard", "E_mean_field", "E_mc"):
            if name in row:
                row[f"bias_{name[2:]}"] = row[name] - row["E_ref"]
        row["wall_s"] = time.perf_counter() - t0
        rows.append(row)
        print(_format(row), flush=True)
    return rows


def grid_agreement(args) -> list[dict]:
    """Mean-field against E_ref on each --grid LO:HI:STEP: the largest relative gap and the
    distance between the two argmins."""
    import diffsense as ds
    from diffsense.solve import Evaluator

    ev = Evaluator(ds.objective(_problem(args, str(args.law_config or LAWS[args.sensor]))))
    out = []
    for text in args.grid:
        lo, hi, step = (float(v) for v in text.split(":"))
        r = np.arange(lo, hi + 0.5 * step, step)
        ref = np.array([ev.e_reference(x) for x in r])
        se = np.array([float(ev.reference(x).e_se) for x in r])
        mf = np.array([np.sqrt(max(ev.e2_soft(x), 0.0)) for x in r])
        gap = np.abs(mf - ref) / ref
        row = {"grid": text, "points": int(r.size), "max_rel_gap": float(gap.max()), "r_max_gap": float(r[gap.argmax()]),
               "argmin_ref": float(r[ref.argmin()]), "argmin_mean_field": float(r[mf.argmin()]),
               "E_ref_min": float(ref.min()), "E_ref_min_se": float(se[ref.argmin()]),
               "E_ref_at_argmin_mean_field": float(ref[mf.argmin()]),
               "r": r.tolist(), "E_ref": ref.tolist(), "E_ref_se": se.tolist(), "E_mean_field": mf.tolist()}
        print(json.dumps({k: v for k, v in row.items() if not isinstance(v, list)}), flush=True)
        out.append(row)
    return out


def _format(row: dict) -> str:
    se = row["E_ref_se"]
    parts = [f"r {row['r']:7.2f}", f"E_ref {row['E_ref']:.4f} +- {se:.4f}"]
    for name in ("hard", "mean_field", "mc"):
        if f"bias_{name}" in row:
            bias = row[f"bias_{name}"]
            parts.append(f"{name} {row['E_' + name]:.4f} ({bias:+.4f} m, {bias / se if se > 0 else float('nan'):+.1f} SE)")
    return " | ".join(parts)


def main_job(args) -> list[dict]:
    """The default main job with the shipped threshold law and with the probabilistic one."""
    import diffsense as ds
    from diffsense.solve import Evaluator

    out = []
    for law in (None, str(args.law_config or LAWS[args.sensor])):
        problem = ds.Problem(sensor=args.sensor, sensor_config=law)
        problem = dataclasses.replace(problem, estimator=dataclasses.replace(problem.estimator, reference_draws=args.draws))
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


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sensor", default="radar", choices=sorted(LAWS))
    p.add_argument("--law-config", type=Path, help="sensor TOML with the probabilistic [detection] law")
    p.add_argument("--scenarios", default="sc01")
    p.add_argument("--variants", type=int, default=1)
    p.add_argument("--points", default="10,20,30,45,60,90", help="HFOV points [deg]; '' for none")
    p.add_argument("--draws", type=int, default=32)
    p.add_argument("--mc-samples", type=int, default=8)
    p.add_argument("--grid", action="append", default=[], metavar="LO:HI:STEP",
                   help="also compare mean-field with E_ref on this HFOV grid [deg] (repeatable)")
    p.add_argument("--main-job", action="store_true")
    p.add_argument("--json", type=Path)
    args = p.parse_args()
    report = {"args": {k: str(v) for k, v in vars(args).items()}, "table": estimator_table(args)}
    if args.grid:
        report["grid"] = grid_agreement(args)
    if args.main_job:
        report["main_job"] = main_job(args)
    if args.json:
        args.json.write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
