"""How well a many-parameter answer's r* interval covers: over independent seeds of a small
two-parameter problem, how often `box_r_star_interval`'s 90 % intervals (each parameter along
its axis through r*, the others held there) hold the large-sample r*, per parameter and both at
once, and how often they hold another seed's r*.

    nice -n 5 python benchmarks/bench_box_r_star_coverage.py [--seeds 30] [--variants 4]
        [--json benchmarks/results/box_r_star_coverage.json] [--render docs/uncertainty.md]
        [--render-only] [--rejudge]

Problem: the radar's HFOV (10-22 deg) and yaw (-10 to 10 deg), sc01 + sc03, the physical
profile's default law (Swerling I), E_ref on 4 detection draws; each seed's r* the argmin of E
on a 9 x 9 grid (a stand-in for the box solve: the grid holds each axis's first nine points,
so the axes cost only their refinement). The large-sample r* is the argmin of E pooled over
BIG_SEEDS independent seeds of BIG_VARIANTS variants per scenario each (E^2 is a mean over the
variants, so the pooled E^2 is the mean of the seeds' E^2): the grid's, then each axis's
parabola vertex (the seeds' intervals are resolved as finely). Each big seed's own r* is kept
beside it: their spread is the large-sample r*'s own sampling error. --render replaces the block between
`<!-- box-r-star-coverage -->` and `<!-- /box-r-star-coverage -->` of a Markdown file.
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import diffsense as ds  # noqa: E402
from _markdown import measured_rows, replace_block  # noqa: E402
from bench_r_star_coverage import _uptime, vertex  # noqa: E402
from diffsense.metrics import LEVEL, RESAMPLES, EstimatorConfig  # noqa: E402
from diffsense.solve import Evaluator  # noqa: E402
from diffsense.study import box_r_star_interval  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
JSON = ROOT / "benchmarks" / "results" / "box_r_star_coverage.json"
PARAMS = {"hfov_deg": (10.0, 22.0), "yaw_deg": (-10.0, 10.0)}
GRID = [np.linspace(lo, hi, 9) for lo, hi in PARAMS.values()]
BIG_SEEDS, BIG_VARIANTS = (10_000, 10_001, 10_002, 10_003), 64


def _evaluator(seed: int, variants: int) -> tuple[Evaluator, np.ndarray]:
    problem = ds.Problem(sensor="radar", scenarios=["sc01", "sc03"], variants=variants, seed=seed, params=PARAMS,
                         estimator=EstimatorConfig(reference_draws=4))
    E = ds.objective(problem)
    return Evaluator(E), np.asarray(E.data.scenario)


def _grid_argmin(ev: Evaluator) -> list[float]:
    points = [np.array(p) for p in itertools.product(*GRID)]
    return [float(v) for v in min(points, key=ev.e_reference)]


def _pooled(evs: list[Evaluator]):
    """E [m] pooled over the evaluators' variants (each scenario's variants equal in number)."""
    return lambda x: float(np.sqrt(np.mean([ev.e_reference(np.asarray(x)) ** 2 for ev in evs])))


def _smooth_r_star(e) -> tuple[list[float], list[float]]:
    """The grid's argmin of `e`, then along each axis in turn (twice) the vertex of the parabola
    through it on 17 points a grid step either side (`bench_r_star_coverage.vertex`: r* of the
    smooth E, not of its last bumps). Returns (that r*, the grid's argmin)."""
    points = [np.array(p) for p in itertools.product(*GRID)]
    coarse = [float(v) for v in min(points, key=e)]
    x = list(coarse)
    for _ in range(2):
        for i, g in enumerate(GRID):
            line = np.unique(np.clip(x[i] + (g[1] - g[0]) * np.linspace(-1.0, 1.0, 17), g[0], g[-1]))
            x[i] = vertex(line, np.array([e(np.array(x[:i] + [v] + x[i + 1:])) for v in line]))
    return x, coarse


def _large_sample_r_star() -> tuple[list[float], list[float], list[list[float]]]:
    """The large-sample r* on the BIG_SEEDS pooled, its grid argmin, and each big seed's own r*."""
    evs = [_evaluator(seed, BIG_VARIANTS)[0] for seed in BIG_SEEDS]
    each = [_smooth_r_star(_pooled([ev]))[0] for ev in evs]
    x, coarse = _smooth_r_star(_pooled(evs))
    print(f"large-sample r*: {x} (grid: {coarse}); each big seed's: {each}", flush=True)
    return x, coarse, each


def rejudged(res: dict, large: tuple[list[float], list[float]]) -> dict:
    """`res` with each row's coverage recomputed against `large` (the seeds' intervals are the
    same for the same seeds: deterministic)."""
    rows = []
    for r in res["rows"]:
        held = np.array([[lo <= t <= hi for t, (lo, hi) in zip(large[0], iv)] for iv in r["intervals"]])
        rows.append(r | {"truth": large[0], "truth_grid": large[1], "truth_each_seed": large[2],
                         "big_seeds": len(BIG_SEEDS), "coverage": [float(v) for v in held.mean(axis=0)],
                         "coverage_both": float(held.all(axis=1).mean())})
    return res | {"rows": rows}


def run(variants: int, seeds: int, large: tuple[list[float], list[float]]) -> dict:
    t0, before = time.perf_counter(), _uptime()
    truth = large[0]
    r_star, intervals = [], []
    for seed in range(seeds):
        ev, strata = _evaluator(seed, variants)
        r_star.append(_grid_argmin(ev))
        axes = box_r_star_interval(ev, r_star[-1], list(PARAMS.values()), strata, of_reference=True, seed=seed)
        intervals.append([a[0] for a in axes])
        print(f"seed {seed}: r* {r_star[-1]}, intervals {intervals[-1]}", flush=True)
    rs = np.asarray(r_star)
    held = np.array([[lo <= t <= hi for t, (lo, hi) in zip(truth, iv)] for iv in intervals])  # [seeds, d]
    others = [np.mean([all(lo <= v <= hi for v, (lo, hi) in zip(rs[j], iv)) for j in range(seeds) if j != i])
              for i, iv in enumerate(intervals)]
    widths = np.array([[hi - lo for lo, hi in iv] for iv in intervals])
    return {"variants": variants, "seeds": seeds, "names": list(PARAMS), "grid": [list(map(float, g)) for g in GRID],
            "truth": truth, "truth_grid": large[1], "truth_each_seed": large[2], "big_seeds": len(BIG_SEEDS),
            "big_variants": BIG_VARIANTS, "r_star": r_star, "intervals": intervals,
            "coverage": [float(v) for v in held.mean(axis=0)], "coverage_both": float(held.all(axis=1).mean()),
            "others_inside_both": float(np.mean(others)),
            "width_median": [float(v) for v in np.median(widths, axis=0)],
            "r_star_mean": [float(v) for v in rs.mean(axis=0)], "r_star_sd": [float(v) for v in rs.std(axis=0, ddof=1)],
            "wall_s": time.perf_counter() - t0, "uptime": [before, _uptime()]}


def _big(row: dict) -> str:
    seeds = row.get("big_seeds", 1)
    per = f"{row['big_variants']} variants per scenario"
    return per if seeds == 1 else f"{seeds} seeds of {per} pooled"


def _spread(row: dict) -> str:
    """The big seeds' own r*, each parameter's range: the large-sample r*'s sampling error."""
    each = np.asarray(row.get("truth_each_seed", []))
    if each.ndim != 2 or len(each) < 2:
        return ""
    spans = ", ".join(f"{n} {lo:.3g}-{hi:.3g}" for n, lo, hi in zip(row["names"], each.min(0), each.max(0)))
    return f"; each seed's own r* alone: {spans}"


def table(res: dict) -> str:
    rows = ["| parameter | variants per scenario | seeds | large-sample r* | coverage of it | median width | "
            "r* over seeds, mean ± SD |", "|---|---|---|---|---|---|---|"]
    for r in res["rows"]:
        for i, name in enumerate(r["names"]):
            rows.append(f"| {name} | {r['variants']} | {r['seeds']} | {r['truth'][i]:.4g} | {100 * r['coverage'][i]:.0f} % | "
                        f"{r['width_median'][i]:.3g} | {r['r_star_mean'][i]:.2f} ± {r['r_star_sd'][i]:.2f} |")
    both = "; ".join(f"{r['variants']} variants: both parameters at once {100 * r['coverage_both']:.0f} %, "
                     f"another seed's r* inside both {100 * r['others_inside_both']:.0f} %" for r in res["rows"])
    loads = [u.split("load average: ")[-1] for r in res["rows"] for u in r["uptime"]]
    return ("\n".join(rows) + f"\n\n{both}. {LEVEL:.0%} intervals, {RESAMPLES} resamples each, seeded by the seed; "
            f"the large-sample r* on {_big(res['rows'][0])}, off the grid (each axis's parabola vertex){_spread(res['rows'][0])}; "
            "`uptime` before and "
            "after: " + "; ".join(loads) + ". Measured with `python benchmarks/bench_box_r_star_coverage.py` on "
            f"{res['meta']['cpus']} cores.")


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seeds", type=int, default=30)
    p.add_argument("--variants", default="4")
    p.add_argument("--json", type=Path, default=JSON)
    p.add_argument("--render", type=Path, default=None)
    p.add_argument("--render-only", action="store_true", help="render the stored JSON, run nothing")
    p.add_argument("--rejudge", action="store_true",
                   help="re-measure the large-sample r* and recompute the stored intervals' coverage of it")
    args = p.parse_args(argv)
    variants = [int(x) for x in args.variants.split(",")]
    if args.rejudge:
        res = rejudged(json.loads(args.json.read_text()), _large_sample_r_star())
        args.json.write_text(json.dumps(res, indent=1) + "\n")
    else:
        large = None if args.render_only else _large_sample_r_star()
        res = measured_rows(args.json, args.render_only, (lambda v=v: run(v, args.seeds, large) for v in variants))
    print(table(res))
    if args.render:
        replace_block(args.render, "box-r-star-coverage", table(res))


if __name__ == "__main__":
    main()
