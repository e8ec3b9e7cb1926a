"""The main job's cost: cold and warm runs, the dense-grid baseline, far background traffic.

    python benchmarks/bench_optimise.py [--model PATH] [--variants 8] [--skip-cold]

1. The default command `python -m diffsense.optimise --param hfov --interval 30 180` in a fresh
   process, twice: with an empty JAX compilation cache (cold) and with the cache the first run
   filled (warm). Target: cold under 90 s on the 2-core reference machine.
2. In one process, on the same objective: the continuous solve (at most 20 objective+gradient
   evaluations) against a dense hard grid at 0.5 deg (301 evaluations); wall-time ratio and E_hard.
3. The same solve with 100 far background vehicles added to every scenario: the run time must
   change by under 20 % (only the vehicles a scene requires are modelled).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax

ROOT = Path(__file__).resolve().parents[1]


def cold_and_warm(model: str | None, variants: int) -> list[tuple[str, float, dict]]:
    rows = []
    with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as out:
        env = dict(os.environ, XDG_CACHE_HOME=cache)
        env.pop("DIFFSENSE_NO_CACHE", None)
        cmd = [sys.executable, "-m", "diffsense.optimise", "--param", "hfov", "--interval", "30", "180",
               "--variants", str(variants), "--out", out, "--quiet"]
        if model:
            cmd += ["--model", model]
        for label in ("cold (empty compilation cache)", "warm (cache from the cold run)"):
            t0 = time.perf_counter()
            subprocess.run(cmd, cwd=ROOT, env=env, check=True, capture_output=True)
            wall = time.perf_counter() - t0
            rows.append((label, wall, json.loads((Path(out) / "result.json").read_text())))
    return rows


def timed_solve(cfg, predictor):
    from diffsense._timing import CompileClock
    from diffsense.metrics import build_problem
    from diffsense.solve import solve

    with CompileClock() as clock:
        problem = build_problem(cfg, predictor=predictor)
        e2_soft, e_hard = problem.objective.solver_fns()
        result = solve(e2_soft, e_hard, (30.0, 180.0))
    return problem, result, clock


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", default=None, help="predictor weights (default: the shipped ones)")
    p.add_argument("--variants", type=int, default=8)
    p.add_argument("--skip-cold", action="store_true")
    args = p.parse_args()
    print(f"jax {jax.__version__} on {jax.default_backend()}, {os.cpu_count()} CPU cores, "
          f"{platform.processor() or platform.machine()}, variants per scenario {args.variants}")

    if not args.skip_cold:
        print("\n1. the default command in a fresh process")
        print(f"{'run':<34} {'wall s':>8} {'compile s':>10} {'run s':>8} {'r* deg':>8} {'E_hard m':>9}")
        for label, wall, res in cold_and_warm(args.model, args.variants):
            print(f"{label:<34} {wall:8.1f} {res['wall_s']['compile']:10.1f} {res['wall_s']['run']:8.1f} "
                  f"{res['r_star']:8.2f} {res['E_hard_star']:9.4f}")

    from diffsense import cli as _cli
    from diffsense.metrics import ProblemConfig
    from diffsense.predictors import load_predictor
    from diffsense.solve import basin_check, dense_grid_search, solve

    _cli.setup_jax(float64=True, compilation_cache=False)
    predictor = load_predictor(args.model)
    cfg = ProblemConfig(variants=args.variants)
    problem, result, clock = timed_solve(cfg, predictor)
    obj = problem.objective
    # Time the solve's own evaluations again now that everything is compiled.
    obj.forget()
    e2_soft, e_hard = obj.solver_fns()
    t0 = time.perf_counter()
    solve(e2_soft, e_hard, (30.0, 180.0))
    solve_s = time.perf_counter() - t0
    obj.forget()
    dense = dense_grid_search(obj.e_hard, (30.0, 180.0), 0.5)
    n_solve = result.evaluations["objective"] + result.evaluations["gradient"] + 2 * len(result.sweep)
    print("\n2. continuous solve versus the dense 0.5-deg hard grid (same objective, compiled)")
    print(f"{'method':<30} {'evaluations':>11} {'wall s':>8} {'r* deg':>8} {'E_hard m':>9}")
    print(f"{'sweep + continuous solve':<30} {n_solve:>11} {solve_s:8.2f} {result.r_star:8.2f} {result.E_hard_star:9.4f}")
    i = dense.best_index
    print(f"{'dense grid, 0.5 deg':<30} {dense.evaluations:>11} {dense.wall_s:8.2f} {dense.r[i]:8.2f} {dense.E_hard[i]:9.4f}")
    print(f"wall-time ratio dense / continuous: {dense.wall_s / solve_s:.1f}x; "
          f"E_hard continuous - dense: {result.E_hard_star - dense.E_hard[i]:+.4f} m")
    why = basin_check(dense, result.r_star, result.E_hard_star, result.bracket)
    print("basin check: " + (why or "r* lies in the basin of the best dense point"))

    print("\n3. far background traffic (100 vehicles per scenario)")
    print(f"{'scene':<26} {'V kept':>7} {'solve wall s':>13}")
    base_v = obj.data.scenes.num_vehicles
    print(f"{'paper scenarios':<26} {base_v:>7} {solve_s:13.2f}")
    bg_problem, _, _ = timed_solve(ProblemConfig(variants=args.variants, background_vehicles=100), predictor)
    bg = bg_problem.objective
    e2_soft, e_hard = bg.solver_fns()
    bg.forget()
    t0 = time.perf_counter()
    solve(e2_soft, e_hard, (30.0, 180.0))
    bg_s = time.perf_counter() - t0
    print(f"{'+100 background each':<26} {bg.data.scenes.num_vehicles:>7} {bg_s:13.2f}")
    print(f"run-time change: {100 * (bg_s / solve_s - 1):+.1f} % (target: under 20 %)")


if __name__ == "__main__":
    main()
