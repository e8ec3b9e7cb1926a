"""The speed/accuracy trade in the user's terms: variants per scenario against wall time and the
width of the intervals a run reports.

    nice -n 5 python benchmarks/bench_intervals.py [--variants 1,2,4,8,16,32] [--seeds 0,1,2]
        [--scenarios sc01,sc03] [--interval 30 180]
        [--json benchmarks/results/intervals_tradeoff.json] [--render docs/uncertainty.md]
        [--render-only]

Problem: radar HFOV over --interval, the physical profile's default laws (Swerling I radar,
answers on E_ref over its detection draws), the default estimator, the given scenarios; one
`diffsense.optimise` run (the main job's search, no figures, not judged) per variant count and
seed, each in this process with JAX's in-memory caches cleared before it and the persistent
compilation cache off, so every run compiles as a fresh process would (the predictor is loaded
once, outside the timed run).

Measured per run, from `Result.to_json()`:

    wall_s            the run: building the problem (scenes, ground truth, compilation) and its search
    E_half_m          half the width of "E_ci", the interval on the answer's E (E_ref(r*)) [m]
    decision_half_m   half the width of the paired interval ("comparisons" "ci") of the
                      second-best sweep step against the best: the interval a user decides with
    decision_unpaired_half_m   the same difference's unpaired interval ("ci_unpaired")
    clear             the paired interval excludes 0 (the best step is told from the second)
    r_star            the answer [deg]; across the seeds its spread (max - min) and sample SD,
                      beside the width of r*'s own interval ("r_star_ci")

One variant per scenario has no interval (null). The JSON holds a list of problems (scenarios
and interval), each with its runs keyed by (variants, seed): a run of some counts keeps the
stored ones' others, and of other problems. --render replaces the block between
`<!-- intervals-table -->` and `<!-- /intervals-table -->` of a Markdown file with the table
rendered from the JSON.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import diffsense as ds  # noqa: E402
from _markdown import replace_block  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
JSON = ROOT / "benchmarks" / "results" / "intervals_tradeoff.json"


def _uptime() -> str:
    try:
        return subprocess.run(["uptime"], capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "load average: " + ", ".join(f"{v:.2f}" for v in os.getloadavg())


def _half(ci) -> float | None:
    return None if ci is None else (ci[1] - ci[0]) / 2.0


def run_one(variants: int, seed: int, args, predictor) -> dict:
    """One `diffsense.optimise` run and what it reports (module docstring)."""
    problem = ds.Problem(sensor="radar", params={"hfov_deg": tuple(args.interval)}, scenarios=args.scenarios,
                         variants=variants, seed=seed)
    jax.clear_caches()
    load = os.getloadavg()[0]
    t = time.perf_counter()
    result = ds.optimise(problem, predictor=predictor, figures=False, judge=False)
    wall = time.perf_counter() - t
    c = result.to_json()
    steps = [x for x in c["comparisons"] if not str(x["a"]).startswith("r* ") and x.get("of", "sweep") == "sweep"]
    second = min(steps, key=lambda x: x["diff_m"]) if steps else None
    ref = c["reference"] or {}
    e = ref["E_ref_star"] if ref.get("answer_on") == "E_ref" else c["E_hard_star"]
    return {"variants": variants, "seed": seed, "wall_s": wall, "compile_s": c["wall_s"].get("compile"),
            "load": [load, os.getloadavg()[0]], "r_star": c["r_star"]["hfov_deg"], "answer_on": ref.get("answer_on"),
            "E_m": e, "E_ci": c["E_ci"], "E_half_m": _half(c["E_ci"]),
            "decision": None if second is None else f"{second['a']} against {second['b']}",
            "decision_diff_m": None if second is None else second["diff_m"],
            "decision_ci": None if second is None else second["ci"],
            "decision_half_m": None if second is None else _half(second["ci"]),
            "decision_unpaired_half_m": None if second is None else _half(second.get("ci_unpaired")),
            "clear": None if second is None or second["ci"] is None else bool(second["ci"][0] > 0.0 or second["ci"][1] < 0.0),
            "r_star_ci": (c.get("r_star_ci") or {}).get("hfov_deg")}


def summarise(runs: list[dict]) -> list[dict]:
    """One row per variant count: medians over its seeds, r*'s spread across them."""
    rows = []
    for n in sorted({r["variants"] for r in runs}):
        rs = sorted((r for r in runs if r["variants"] == n), key=lambda r: r["seed"])

        def median(key: str, rs=rs) -> float | None:
            values = [r[key] for r in rs if r[key] is not None]
            return statistics.median(values) if values else None

        for r in rs:
            ci = r.get("r_star_ci")
            r["r_star_ci_width"] = None if ci is None else ci[1] - ci[0]
        stars = [r["r_star"] for r in rs]
        clear = [r["clear"] for r in rs if r["clear"] is not None]
        rows.append({"variants": n, "seeds": [r["seed"] for r in rs], "wall_s": median("wall_s"),
                     "compile_s": median("compile_s"), "E_m": median("E_m"), "E_half_m": median("E_half_m"),
                     "decision_half_m": median("decision_half_m"),
                     "decision_unpaired_half_m": median("decision_unpaired_half_m"),
                     "clear": sum(clear), "with_interval": len(clear), "r_star": stars,
                     "r_star_spread": max(stars) - min(stars),
                     "r_star_sd": statistics.stdev(stars) if len(stars) > 1 else None,
                     "r_star_ci_width": median("r_star_ci_width")})
    return rows


def _m(x: float | None, spec: str = ".2f") -> str:
    return "none" if x is None else f"{x:{spec}}"


def render(markdown: Path, res: dict) -> None:
    """The block "intervals-table" of `markdown`: one table a problem, each with its load."""
    body = []
    for prob in res["problems"]:
        lo, hi = prob["interval"]
        seeds = sorted({s for row in prob["rows"] for s in row["seeds"]})
        loads = [v for r in prob["runs"] for v in r["load"]]
        body += [f"**Radar HFOV over [{lo:g}, {hi:g}] deg**, {', '.join(prob['scenarios'])}, seeds "
                 f"{', '.join(map(str, seeds))} (1-minute load {min(loads):.1f}-{max(loads):.1f} during the runs; "
                 f"`uptime` before them: {'; '.join(u[0].split('load average: ')[-1] for u in prob['uptime'])}):",
                 "", *table(prob), "", *([reading(prob), ""] if reading(prob) else [])]
    body.append(f"Measured with `python benchmarks/bench_intervals.py` on {res['meta']['cpus']} cores.")
    replace_block(markdown, "intervals-table", "\n".join(body))
    print(f"rendered the tables into {markdown}")


def reading(prob: dict) -> str:
    """A sentence on the problem's trade, from the fewest variants whose interval is more than the
    range of its own resamples (more than 2: docs/uncertainty.md) to the most."""
    rows = [r for r in summarise(prob["runs"]) if r["with_interval"] and r["variants"] > 2]
    if len(rows) < 2:
        return ""
    a, b = rows[0], rows[-1]
    return (f"From {a['variants']} to {b['variants']} variants per scenario the run's wall time grows "
            f"{b['wall_s'] / a['wall_s']:.1f}-fold, the ± on E(r*) goes from {a['E_half_m']:.2f} to "
            f"{b['E_half_m']:.2f} m and the paired ± on the decision from {a['decision_half_m']:.2f} to "
            f"{b['decision_half_m']:.2f} m; r* spreads over {a['r_star_spread']:.1f} deg across the seeds at "
            f"{a['variants']} variants and {b['r_star_spread']:.1f} deg at {b['variants']}.")


def table(prob: dict) -> list[str]:
    """One problem's rows (summarised again from its runs) as a Markdown table."""
    lines = ["| variants per scenario | wall time [s] | E(r*) [m] | ± on E(r*) [m] | ± on best - second, paired [m] "
             "| unpaired [m] | best told from second | r* over seeds [deg] | r* spread [deg] | r* interval width [deg] |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for row in summarise(prob["runs"]):
        told = f"{row['clear']} of {row['with_interval']}" if row["with_interval"] else "no interval"
        lines.append(f"| {row['variants']} | {row['wall_s']:.0f} | {row['E_m']:.2f} | {_m(row['E_half_m'])} | "
                     f"{_m(row['decision_half_m'])} | {_m(row['decision_unpaired_half_m'])} | {told} | "
                     f"{', '.join(f'{r:.1f}' for r in row['r_star'])} | {row['r_star_spread']:.1f} | "
                     f"{_m(row['r_star_ci_width'], '.1f')} |")
    return lines


def _save(path: Path, res: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(res, indent=1) + "\n")
    print(f"wrote {path}", flush=True)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--variants", default="1,2,4,8,16,32")
    p.add_argument("--seeds", default="0,1,2")
    p.add_argument("--scenarios", default="sc01,sc03")
    p.add_argument("--interval", type=float, nargs=2, default=(30.0, 180.0), metavar=("LO", "HI"))
    p.add_argument("--json", type=Path, default=JSON)
    p.add_argument("--render", type=Path, default=None)
    p.add_argument("--render-only", action="store_true", help="render the stored JSON, run nothing")
    args = p.parse_args(argv)
    args.scenarios = [s for s in args.scenarios.split(",") if s]
    if args.render_only:
        res = json.loads(args.json.read_text())
    else:
        res = json.loads(args.json.read_text()) if args.json.exists() else {"problems": []}
        res["meta"] = {"machine": platform.platform(), "cpus": os.cpu_count(), "jax": jax.__version__}
        key = {"sensor": "radar", "scenarios": args.scenarios, "interval": list(args.interval)}
        prob = next((q for q in res["problems"] if {k: q[k] for k in key} == key), None)
        if prob is None:  # a problem not stored yet; the others are kept as they are
            prob = key | {"uptime": [], "runs": [], "rows": []}
            res["problems"].append(prob)
        prob["uptime"].append([_uptime(), None])
        runs = {(r["variants"], r["seed"]): r for r in prob["runs"]}
        predictor = ds.predictors.load_predictor(None)
        t0 = time.perf_counter()
        for n in (int(v) for v in args.variants.split(",") if v):
            for seed in (int(s) for s in args.seeds.split(",") if s):
                run = run_one(n, seed, args, predictor)
                runs[(n, seed)] = run
                print(f"[{time.perf_counter() - t0:6.0f} s] {n} variants, seed {seed}: {run['wall_s']:.0f} s, "
                      f"r* {run['r_star']:.2f}, E {run['E_m']:.3f} ± {_m(run['E_half_m'], '.3f')} m, "
                      f"decision ± {_m(run['decision_half_m'], '.3f')} m", flush=True)
                prob["runs"] = [runs[k] for k in sorted(runs)]
                prob["rows"] = summarise(prob["runs"])
                prob["uptime"][-1][1] = _uptime()
                _save(args.json, res)  # after every run: a stopped run keeps its rows
    for prob in res["problems"]:
        print(f"radar HFOV {prob['interval']}, {', '.join(prob['scenarios'])}")
        print("\n".join(table(prob)))
    if args.render:  # from the JSON as written
        render(args.render, res)


if __name__ == "__main__":
    main()
