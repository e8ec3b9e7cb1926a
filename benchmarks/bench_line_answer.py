"""One optimum, one answer: the main job's search on E_ref against the 1-deg dense reference grid.

    nice -n 5 python benchmarks/bench_line_answer.py [--intervals 5:60,30:180] [--dense-step 1]
        [--methods brent,secant,brent-whole] [--json benchmarks/results/line_answer.json]
        [--render docs/solver.md]

Problem: the main job's, radar HFOV over each interval, the physical profile (Swerling I radar),
the default scenarios and variants, E_ref on 32 detection draws (common random numbers: E_ref
is a deterministic function of r for the seed). The dense reference grid evaluates E_ref every
--dense-step deg, ends included, on the same compiled program.

Methods, each through `diffsense.optimise` on the same objective (fresh memos):

    brent        the default under a probabilistic law (`SolveConfig.method = "auto"`): the
                 paper's stepped sweep, then Brent's bounded minimisation of E_ref's values in
                 the best step's bracket
    secant       the gradient continuation (`method = "secant"`): the sweep, roots of the
                 straight-through dE^2/dr at tau 4, 2, 1 (the gradient of 8 relaxed draws,
                 the value E_ref on all 32), candidates and the polish on E_ref
    brent-whole  bounded Brent on E_ref over the whole interval with no sweep (the count the
                 issue compares against), plus the interval's two ends

Counted: every program of the answer's search (sweep steps, values, value-and-gradients; a
value-and-gradient is one program), and the programs until the best E_ref seen is within 0.1 %
of the dense grid's best. Writes the JSON and prints a table; --render replaces the block
between `<!-- line-answer-table -->` and `<!-- /line-answer-table -->` of a Markdown file. The
JSON keeps the dense grid's E_ref beside the runs; intervals not given keep their stored entry.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import diffsense as ds  # noqa: E402
from diffsense.solve import Evaluator, SolveConfig, brent_minimise  # noqa: E402
from _markdown import replace_block  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
METHODS = ("brent", "secant", "brent-whole")
WITHIN = 1e-3


def _first_within(values: list[float], target: float) -> int | None:
    best = float("inf")
    for i, v in enumerate(values, 1):
        best = min(best, v)
        if best <= target:
            return i
    return None


def _by_job(problem, E, method: str) -> dict:
    events: list[dict] = []
    t = time.perf_counter()
    result = ds.optimise(problem.replace(solve=SolveConfig(method=method)), E=E, figures=False, judge=False,
                         on_evaluation=events.append)
    wall = time.perf_counter() - t
    programs = len(result.solve.sweep) + result.solve.evaluations["objective"] + result.solve.evaluations["gradient"]
    # the search's programs come first; a soft value under straight-through is E_ref itself
    values = [e["E_m"] for e in events[:programs] if e["kind"] in ("reference", "soft")]
    return {"r_star": result.r_star["hfov_deg"], "E_ref_star": result.reference["E_ref_star"],
            "programs": programs, "values": values, "wall_s": wall, "notes": list(result.solve.notes)}


def _whole(ev: Evaluator, lo: float, hi: float, xtol: float, budget: int) -> dict:
    values: list[float] = []

    def f(r):
        values.append(ev.e_reference(float(r)))
        return values[-1]

    t = time.perf_counter()
    r, e, _ = brent_minimise(f, lo, hi, xtol=xtol, max_evaluations=budget)
    for end in (lo, hi):
        if f(end) < e:
            r, e = end, values[-1]
    return {"r_star": r, "E_ref_star": e, "programs": len(values), "values": values,
            "wall_s": time.perf_counter() - t, "notes": []}


def compare(lo: float, hi: float, args) -> dict:
    load = os.getloadavg()
    problem = ds.Problem(sensor="radar", params={"hfov_deg": (lo, hi)})
    E = ds.objective(problem)
    ev = Evaluator(E)
    t = time.perf_counter()
    grid = [lo + i * args.dense_step for i in range(round((hi - lo) / args.dense_step) + 1)]
    dense = [(ev.e_reference(r), r) for r in grid]
    e_best, r_best = min(dense)
    out = {"interval": [lo, hi], "dense": {"step": args.dense_step, "points": len(grid), "r_best": r_best,
                                           "E_ref_best": e_best, "wall_s": time.perf_counter() - t,
                                           "r": grid, "E_ref": [e for e, _ in dense]},
           "methods": {}}
    target = e_best * (1.0 + WITHIN)
    for method in args.methods:
        print(f"[{lo:g}, {hi:g}] {method}", flush=True)
        if method == "brent-whole":
            run = _whole(Evaluator(E), lo, hi, SolveConfig().xtol_rel * (hi - lo), 200)
        else:
            run = _by_job(problem, E, method)
        run["gap_pct"] = 100.0 * (run["E_ref_star"] / e_best - 1.0)
        run["programs_to_within_0p1pct"] = _first_within(run.pop("values"), target)
        out["methods"][method] = run
    out["load"] = [load[0], os.getloadavg()[0]]  # each interval's own: a re-run keeps the others'
    return out


def table(res: dict) -> list[str]:
    rows = ["| interval [deg] | dense best (1 deg) | method | r* [deg] | E_ref(r*) [m] | above the dense best | "
            "programs | programs to within 0.1 % |", "|---|---|---|---|---|---|---|---|"]
    for iv in res["intervals"]:
        lo, hi = iv["interval"]
        d = iv["dense"]
        for name, m in iv["methods"].items():
            hit = m["programs_to_within_0p1pct"]
            rows.append(f"| {lo:g}-{hi:g} | {d['E_ref_best']:.4f} m at {d['r_best']:g} | {name} | {m['r_star']:.3f} | "
                        f"{m['E_ref_star']:.4f} | {m['gap_pct']:+.3f} % | {m['programs']} | "
                        f"{'never' if hit is None else hit} |")
    return rows


def render(markdown: Path, res: dict) -> None:
    loads = [iv.get("load", [res["meta"]["load_before"][0], res["meta"]["load_after"][0]]) for iv in res["intervals"]]
    load = min(a for a, _ in loads), max(b for _, b in loads)
    body = "\n".join(table(res) + ["", "Programs are counted, not timed. Measured with "
                                   f"`python benchmarks/bench_line_answer.py` "
                                   f"(load {load[0]:.1f}-{load[1]:.1f} on {res['meta']['cpus']} cores)."])
    replace_block(markdown, "line-answer-table", body)
    print(f"rendered the table into {markdown}")


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--intervals", default="5:60,30:180")
    p.add_argument("--dense-step", type=float, default=1.0)
    p.add_argument("--methods", default=",".join(METHODS))
    p.add_argument("--json", type=Path, default=ROOT / "benchmarks" / "results" / "line_answer.json")
    p.add_argument("--render", type=Path, default=None)
    p.add_argument("--render-only", action="store_true", help="render the stored JSON, run nothing")
    args = p.parse_args(argv)
    args.methods = [m for m in args.methods.split(",") if m]
    unknown = sorted(set(args.methods) - set(METHODS))
    if unknown:
        raise SystemExit(f"error: unknown method {unknown[0]} (known: {', '.join(METHODS)})")
    if args.render_only:
        res = json.loads(args.json.read_text())
    else:
        load = os.getloadavg()
        intervals = [tuple(float(v) for v in iv.split(":")) for iv in args.intervals.split(",")]
        fresh = [compare(lo, hi, args) for lo, hi in intervals]
        # intervals not run again keep their stored results
        kept = json.loads(args.json.read_text())["intervals"] if args.json.exists() else []
        runs = {tuple(iv["interval"]): iv for iv in kept} | {tuple(iv["interval"]): iv for iv in fresh}
        res = {"intervals": [runs[k] for k in sorted(runs)],
               "meta": {"machine": platform.platform(), "cpus": os.cpu_count(), "jax": jax.__version__,
                        "load_before": load, "load_after": os.getloadavg(),
                        "args": {k: str(v) for k, v in vars(args).items()}}}
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(res, indent=1) + "\n")
        print(f"wrote {args.json}")
    print("\n".join(table(res)))
    if args.render:
        render(args.render, res)


if __name__ == "__main__":
    main()
