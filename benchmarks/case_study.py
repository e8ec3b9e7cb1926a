"""The paper's case study as data: every table notebook 04 and docs/case-study.md show.

    python benchmarks/case_study.py --json OUT.json [--weights shipped,ngsim] [--profiles physical,paper]
        [--scenarios sc01,...] [--variants 8] [--steps 30,60,90,120,150,180] [--ngsim PATH]

For each predictor weights x sensor profile x sensor (radar with the fills zero, hold and interp;
camera with its profile's fill), hard detections at the paper's HFOV steps: E_hard (Eq. 12)
pooled and per scenario, the "tracked" question (E over the instants whose target is detected in
the 3 s window, and the missed share), the coverage shares, and per scenario the RMSE at each
horizon step of the ground-truth-input and the sensor-input predictions against the true future
(the paper's Figs. 6 and 7). Everything comes from `diffsense.solve.Evaluator.breakdown` and
`Evaluator.hard`; one compiled problem per row of the run list, one hard evaluation per step.
Intervals from the scene sample, as the main job's (`diffsense.study`): each step's pooled
"E_ci" and its breakdown parts' (by scenario, coverage, horizon step); each run's "comparisons",
every step against its best step, paired; and the file's "comparisons", radar against camera at
each step (each profile with its own fill), paired over the scenes both saw (same seed).
`--json -` prints the JSON. Without the NGSIM checkpoint, `ngsim` is skipped with a note.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import jax
import numpy as np

import diffsense as ds
from diffsense import cli, solve
from diffsense.metrics import estimable
from diffsense.predictors import load_predictor
from diffsense.study import answer_ci, breakdown_intervals, paired_comparison

ROOT = Path(__file__).resolve().parents[1]
NGSIM_DEFAULT = ROOT.parent / "shared" / "weights" / "ngsim" / "cslstm_no_m.tar"
PROFILE_FILL = {"physical": "hold", "paper": "zero"}  # each profile's own fill (configs/sensors/*)


def runs(profiles):
    """(profile, sensor, fill) of every problem: radar with the three fills, camera with its own."""
    out = []
    for profile in profiles:
        out += [(profile, "radar", f) for f in ("zero", "hold", "interp")]
        out.append((profile, "camera", PROFILE_FILL[profile]))
    return out


def one_run(predictor, profile, sensor, fill, args) -> tuple[dict, dict]:
    """One problem's steps (the JSON's run), and each step's `SceneSums` with the strata (for the
    radar-against-camera comparisons)."""
    problem = ds.Problem(sensor=sensor, params={"hfov_deg": (min(args.steps), max(args.steps))},
                         scenarios=args.scenarios, variants=args.variants, profile=profile, fill=fill, seed=0)
    t0 = time.perf_counter()
    ev = solve.Evaluator(ds.objective(problem, predictor=predictor))
    strata = np.asarray(ev.objective.data.scenario)
    sums = {r: ev.scene_sums(r, of_reference=False) for r in args.steps}  # E_hard: each detection at its median
    steps = []
    for r in args.steps:
        b = breakdown_intervals(ev, r, ev.breakdown(r, of_reference=False), of_reference=False, seed=problem.seed)
        steps.append({"r": r, "E_hard": b["E_hard"], "E_ci": answer_ci(ev, r, seed=problem.seed, of_reference=False),
                      "tracked": b["tracked"], "coverage": b["coverage"],
                      "by_scenario": b["by_scenario"], "by_horizon": b["by_horizon"],
                      "rmse_sensor": np.asarray(ev.hard(r).rmse_sensor).tolist()})
    gt = np.asarray(ev.hard(args.steps[0]).rmse_gt).tolist()  # [S, 25]; the same at every step
    e = {s["r"]: s["E_hard"] for s in steps}
    best = min(args.steps, key=e.__getitem__)
    comparisons = [paired_comparison(f"{r:g} deg", f"{best:g} deg", e[r], e[best], sums[r], sums[best], strata,
                                     problem.seed) for r in args.steps if r != best]
    run = {"profile": profile, "sensor": sensor, "fill": fill, "steps": steps, "rmse_gt": gt,
           "comparisons": comparisons, "scenarios": list(ev.objective.scenario_names),
           "wall_s": time.perf_counter() - t0}
    return run, {"sums": sums, "strata": strata, "seed": problem.seed}


def sensor_comparisons(runs: list[dict], kept: dict, steps: list[float]) -> list[dict]:
    """Radar against camera at each step, each profile with its own fill, paired over the scenes
    both saw: {"weights", "profile", "r", and `paired_comparison`'s keys ("of": "sensors")}."""
    out = []
    by_key = {(r["weights"], r["profile"], r["sensor"], r["fill"]): i for i, r in enumerate(runs)}
    for (w, profile, sensor, fill), i in by_key.items():
        j = by_key.get((w, profile, "camera", PROFILE_FILL[profile]))
        if sensor != "radar" or fill != PROFILE_FILL[profile] or j is None:
            continue
        a, b = kept[i], kept[j]
        if not (np.array_equal(a["strata"], b["strata"]) and estimable(a["strata"])):
            continue
        for k, r in enumerate(steps):
            out.append({"weights": w, "profile": profile, "r": r} | paired_comparison(
                f"radar at {r:g} deg", f"camera at {r:g} deg", runs[i]["steps"][k]["E_hard"],
                runs[j]["steps"][k]["E_hard"], a["sums"][r], b["sums"][r], a["strata"], a["seed"], of="sensors"))
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--json", required=True, help="output file ('-': stdout)")
    p.add_argument("--weights", default="shipped,ngsim")
    p.add_argument("--profiles", default="physical,paper")
    p.add_argument("--scenarios", default="sc01,sc02,sc03,sc04,sc05,sc06")
    p.add_argument("--variants", type=int, default=8)
    p.add_argument("--steps", default="30,60,90,120,150,180")
    p.add_argument("--ngsim", type=Path, default=NGSIM_DEFAULT, help="the published single-mode checkpoint")
    args = p.parse_args(argv)
    args.scenarios = args.scenarios.split(",")
    args.steps = [float(s) for s in args.steps.split(",")]
    cli.setup_jax(float64=True, compilation_cache=True)
    predictors, notes = {}, []
    for w in args.weights.split(","):
        if w == "ngsim" and not args.ngsim.is_file():
            notes.append(f"ngsim skipped: {args.ngsim} not present")
            continue
        predictors[w] = load_predictor(args.ngsim if w == "ngsim" else None)
    out = {"machine": {"jax": jax.__version__, "backend": jax.default_backend(), "cpus": os.cpu_count(),
                       "processor": platform.processor() or platform.machine(),
                       "load_before": os.getloadavg()},
           "variants": args.variants, "steps_deg": args.steps, "notes": notes,
           "validation_rmse_m": {w: pr.validation_rmse_m for w, pr in predictors.items()}, "runs": []}
    t0 = time.perf_counter()
    kept = []
    for w, predictor in predictors.items():
        for profile, sensor, fill in runs(args.profiles.split(",")):
            run, sums = one_run(predictor, profile, sensor, fill, args)
            run["weights"] = w
            out["runs"].append(run)
            kept.append(sums)
            e = " ".join(f"{s['E_hard']:.3f}" for s in run["steps"])
            print(f"{w:>7} {profile:>8} {sensor:>6} fill={fill:<6} {run['wall_s']:6.1f} s  E_hard: {e}",
                  file=sys.stderr, flush=True)
    out["comparisons"] = sensor_comparisons(out["runs"], kept, args.steps)
    out["wall_s"] = time.perf_counter() - t0
    out["machine"]["load_after"] = os.getloadavg()
    text = json.dumps(out, indent=1)
    if args.json == "-":
        print(text)
    else:
        Path(args.json).write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
