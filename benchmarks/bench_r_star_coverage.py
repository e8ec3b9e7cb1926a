"""How well r*'s interval covers: over independent seeds of a small problem, how often
`argmin_ci`'s 90 % interval holds the large-sample r*, and how often it holds another seed's r*.

    nice -n 5 python benchmarks/bench_r_star_coverage.py [--seeds 40] [--variants 4,8]
        [--answers E_ref,E_hard] [--json benchmarks/results/r_star_coverage.json]
        [--render docs/uncertainty.md] [--render-only]

Problem: radar HFOV, sc01 + sc03, the physical profile's default laws (Swerling I radar), each
seed's variants per scenario as given; E evaluated on a 1-deg grid (the job makes its points
dense where the resamples' picks fall; a grid does it everywhere), r* the grid point of least E.
Two answers: E_ref on 4 detection draws (what a probabilistic law's answer is chosen on; grid
10-22 deg) and E_hard, each detection at its median (the threshold law's; grid 5-40 deg). The
large-sample r* is the same argmin with 128 variants per scenario on seed 10000.

Per row: coverage (the share of seeds whose interval holds the large-sample r*), the share of
the other seeds' r* inside each seed's interval (a re-solve on other traffic), the median
interval width, and r*'s mean and SD over the seeds. --render replaces the block between
`<!-- r-star-coverage -->` and `<!-- /r-star-coverage -->` of a Markdown file with the table
rendered from the JSON.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import diffsense as ds  # noqa: E402
from _markdown import measured_rows, replace_block  # noqa: E402
from diffsense.metrics import LEVEL, RESAMPLES, EstimatorConfig, argmin_ci  # noqa: E402
from diffsense.solve import Evaluator  # noqa: E402
from diffsense.study import r_star_interval  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
JSON = ROOT / "benchmarks" / "results" / "r_star_coverage.json"
GRIDS = {"E_ref": np.arange(10.0, 22.01, 1.0), "E_hard": np.arange(5.0, 40.01, 1.0)}
BIG_SEED, BIG_VARIANTS = 10_000, 128


def _uptime() -> str:
    try:
        return subprocess.run(["uptime"], capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "load average: " + ", ".join(f"{v:.2f}" for v in os.getloadavg())


def _sums(answer: str, seed: int, variants: int):
    problem = ds.Problem(sensor="radar", scenarios=["sc01", "sc03"], variants=variants, seed=seed,
                         params={"hfov": (5.0, 60.0)}, estimator=EstimatorConfig(reference_draws=4))
    E = ds.objective(problem)
    ev = Evaluator(E)
    sums = [ev.scene_sums(float(r), of_reference=answer == "E_ref") for r in GRIDS[answer]]
    return sums, np.asarray(E.data.scenario), ev


def vertex(line: np.ndarray, e: np.ndarray) -> float:
    """The minimiser of the least-squares parabola through E on `line`, kept within it: r* of
    the smooth E a large sample estimates, not of its last bumps (E_ref on a few detection draws
    is a sum of steps in r, and its argmin on a fine line sits on whichever step happens lowest)."""
    a, b, _ = np.polyfit(line, e, 2)
    return float(np.clip(-b / (2.0 * a), line[0], line[-1])) if a > 0 else float(line[int(np.argmin(e))])


def _smooth_argmin(ev: Evaluator, r0: float, of_reference: bool) -> float:
    """The large-sample r*: `vertex` of E on 17 points 1/4 deg apart around the grid's argmin r0."""
    line = r0 + np.linspace(-2.0, 2.0, 17)
    ones = np.ones((1, ev.objective.data.scenario.shape[0]))
    return vertex(line, np.array([float(ev.scene_sums(float(r), of_reference).e(ones)[0]) for r in line]))


def _argmin(grid: np.ndarray, sums, strata) -> float:
    ones = np.ones((1, strata.size))
    return float(grid[np.argmin([float(s.e(ones)[0]) for s in sums])])


def run(answer: str, variants: int, seeds: int, refined: bool = False) -> dict:
    """One row. `refined`: each seed's interval as the job makes it (`r_star_interval`: the grid,
    then points made dense where the picks fall, on the problem's 5-60 deg interval) against the
    large-sample r* off the grid (`_smooth_argmin`); else the grid's interval against the grid's r*."""
    grid, on_ref = GRIDS[answer], answer == "E_ref"
    t0, before = time.perf_counter(), _uptime()
    sums, strata, ev = _sums(answer, BIG_SEED, BIG_VARIANTS)
    truth = _argmin(grid, sums, strata)
    truth = _smooth_argmin(ev, truth, on_ref) if refined else truth
    r_star, intervals = [], []
    for seed in range(seeds):
        sums, strata, ev = _sums(answer, seed, variants)
        r_star.append(_argmin(grid, sums, strata))
        intervals.append(list(r_star_interval(ev, strata, of_reference=on_ref, seed=seed, interval=(5.0, 60.0))[0]
                              if refined else argmin_ci(grid, sums, strata, level=LEVEL, seed=seed)))
        print(f"{answer} {variants} variants seed {seed}: r* {r_star[-1]:g}, interval {intervals[-1]}", flush=True)
    rs = np.asarray(r_star)
    inside_others = [float(np.mean((np.delete(rs, i) >= lo) & (np.delete(rs, i) <= hi)))
                     for i, (lo, hi) in enumerate(intervals)]
    return {"answer": answer, "variants": variants, "seeds": seeds, "grid": [float(grid[0]), float(grid[-1]), 1.0],
            "refined": refined,
            "truth": truth, "r_star": r_star, "intervals": intervals,
            "coverage": float(np.mean([lo <= truth <= hi for lo, hi in intervals])),
            "others_inside": float(np.mean(inside_others)),
            "width_median": float(np.median([hi - lo for lo, hi in intervals])),
            "at_grid_end": int(sum(lo <= grid[0] or hi >= grid[-1] for lo, hi in intervals)),
            "r_star_mean": float(rs.mean()), "r_star_sd": float(rs.std(ddof=1)),
            "wall_s": time.perf_counter() - t0, "uptime": [before, _uptime()]}


def table(res: dict) -> str:
    rows = ["| answer on | interval's points | variants per scenario | seeds | large-sample r* [deg] | coverage of it | "
            "other seeds' r* inside | median width [deg] | r* over seeds, mean ± SD [deg] | intervals at a grid end |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    for r in res["rows"]:
        points = "grid, made dense (the job's)" if r.get("refined") else "1-deg grid"
        rows.append(f"| {r['answer']} | {points} | {r['variants']} | {r['seeds']} | {r['truth']:.4g} | {100 * r['coverage']:.0f} % | "
                    f"{100 * r['others_inside']:.0f} % | {r['width_median']:.3g} | {r['r_star_mean']:.1f} ± {r['r_star_sd']:.1f} | {r['at_grid_end']} |")
    loads = [u.split("load average: ")[-1] for r in res["rows"] for u in r["uptime"]]
    return ("\n".join(rows) + f"\n\n{LEVEL:.0%} intervals, {RESAMPLES} resamples each, seeded by the seed; "
            + "an interval at a grid end might be wider on a wider grid (one that holds the large-sample "
            + "r* holds it either way); "
            + "`uptime` before and after each row: " + "; ".join(loads)
            + ". Measured with `python benchmarks/bench_r_star_coverage.py` on " + f"{res['meta']['cpus']} cores.")


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seeds", type=int, default=40)
    p.add_argument("--variants", default="4,8")
    p.add_argument("--answers", default="E_ref,E_hard")
    p.add_argument("--refined", action="store_true",
                   help="each seed's interval made dense as the job makes it, against a large-sample r* off the grid")
    p.add_argument("--append", action="store_true", help="add the rows to the stored JSON's")
    p.add_argument("--json", type=Path, default=JSON)
    p.add_argument("--render", type=Path, default=None)
    p.add_argument("--render-only", action="store_true", help="render the stored JSON, run nothing")
    args = p.parse_args(argv)
    answers = args.answers.split(",")
    for answer in answers:
        if answer not in GRIDS:
            raise SystemExit(f"error: --answers takes E_ref and E_hard, got {answer!r}")
    variants = [int(x) for x in args.variants.split(",")]
    res = measured_rows(args.json, args.render_only,
                        (lambda a=a, v=v: run(a, v, args.seeds, args.refined) for a in answers for v in variants),
                        keep=args.append)
    print(table(res))
    if args.render:
        replace_block(args.render, "r-star-coverage", table(res))


if __name__ == "__main__":
    main()
