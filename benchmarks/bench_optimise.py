"""The main job's cost: cold and warm runs, the dense-grid baseline, far background traffic.

    python benchmarks/bench_optimise.py [--model PATH] [--variants 8] [--scenarios sc01,...]
        [--skip-cold | --processes-only] [--repeat 1] [--python EXE] [--flags "..."] [--dense-step 0.5]
        [--json PATH]

1. The default command `python -m diffsense.optimise --param hfov --interval 30 180` in fresh
   processes: first with an empty JAX compilation cache (cold), then --repeat times with the
   cache the cold run filled (warm). Target: cold under 90 s on the 2-core reference machine.
   `--python EXE` runs the command with another environment's interpreter, e.g. a virtual
   environment with an older commit installed (`pip install -e` of a `git worktree`), to compare
   two versions of the main job as whole processes; `--flags` adds options to the command (e.g.
   "--predictor-dtype bfloat16"); `--processes-only` stops after this part.
2. In one process, on the same objective (`diffsense.objective`): the main job's search
   (`diffsense.optimise` on the built objective, figures off: the stepped sweep and the
   continuous solve, at most 20 objective+gradient evaluations) against a dense hard grid every
   --dense-step deg (301 evaluations at 0.5); wall-time ratio and E_hard.
3. The same search with 100 far background vehicles added to every scenario: the run time must
   change by under 20 % (only the vehicles a scene requires are modelled).

Columns of 2: evaluations = the continuous solve's objective and gradient evaluations plus a
hard and a soft one per sweep step (the solver's own count); programs = the compiled objective
programs that actually ran (`Result.programs_run`: memoised points are not run again).
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
import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _r_star(content: dict) -> float:
    """r* of a result.json: a number before the library's `Result`, {name: number} after."""
    r = content["r_star"]
    return float(next(iter(r.values())) if isinstance(r, dict) else r)


def _describe(repo: Path) -> str:
    """The checkout a command runs from, with its commit when it is a git checkout."""
    try:
        commit = subprocess.run(["git", "-C", str(repo), "log", "-1", "--format=%h %s"], capture_output=True,
                                text=True, check=True, timeout=30).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        commit = "not a git checkout"
    return f"{repo} ({commit[:80]})"


def cold_and_warm(model: str | None, variants: int, scenarios: str | None, repeat: int,
                  python: str = sys.executable, flags: str = "") -> list[dict]:
    """Wall time [s] and result.json of the default command in fresh processes: one cold (empty
    compilation cache), then `repeat` warm ones (the cache the cold run filled). `python`: the
    interpreter whose installed diffsense runs (default: this one); `flags`: more options of the
    command, split on spaces."""
    rows = []
    with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as out:
        env = dict(os.environ, XDG_CACHE_HOME=cache)
        env.pop("DIFFSENSE_NO_CACHE", None)
        cmd = [python, "-m", "diffsense.optimise", "--param", "hfov", "--interval", "30", "180",
               "--variants", str(variants), "--out", out, "--quiet"]
        if scenarios:
            cmd += ["--scenarios", scenarios]
        if model:
            cmd += ["--model", model]
        cmd += flags.split()
        labels = ["cold (empty compilation cache)"] + [f"warm {i + 1} (cache of the cold run)" for i in range(repeat)]
        for label in labels:
            t0 = time.perf_counter()
            done = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
            wall = time.perf_counter() - t0
            if done.returncode != 0:
                raise SystemExit(f"error: {' '.join(cmd)} exited {done.returncode}:\n{done.stderr[-2000:]}")
            content = json.loads((Path(out) / "result.json").read_text())
            rows.append({"run": label, "wall_s": wall, "compile_s": content["wall_s"]["compile"],
                         "run_s": content["wall_s"]["run"], "r_star": _r_star(content),
                         "programs_compiled": content["wall_s"]["programs_compiled"],
                         "programs_lowered": content["wall_s"].get("programs_lowered"),  # absent before f6558a2
                         "E_hard_star": content["E_hard_star"]})
    return rows


def timed_search(problem, E) -> tuple[object, float]:
    """The main job's search on a built (and compiled) objective, with its evaluations not
    memoised from an earlier call (`diffsense.optimise` makes a fresh evaluator): (Result, s)."""
    import diffsense as ds

    t0 = time.perf_counter()
    result = ds.optimise(problem, E=E, figures=False)
    return result, time.perf_counter() - t0


def build_and_search(problem, predictor):
    """The objective built, and the search run once (compiling every program it needs)."""
    import diffsense as ds

    E = ds.objective(problem, predictor=predictor)
    ds.optimise(problem, E=E, figures=False)
    return E


def solve_against_dense(problem, predictor, dense_step: float) -> tuple[object, dict]:
    """Part 2: (the objective, the row of numbers)."""
    from diffsense import solve

    E = build_and_search(problem, predictor)
    result, solve_s = timed_search(problem, E)
    lo, hi = problem.params["hfov_deg"]
    dense = solve.dense_grid_search(solve.Evaluator(E).e_hard, (lo, hi), dense_step)
    s = result.solve
    i = dense.best_index
    return E, {
        "solve": {"evaluations": s.evaluations["objective"] + s.evaluations["gradient"] + 2 * len(s.sweep),
                  "programs": sum(result.programs_run["solve"].values()), "wall_s": solve_s,
                  "r_star": result.r_star["hfov_deg"], "E_hard": result.E_hard_star},
        "dense": {"step": dense_step, "evaluations": dense.evaluations, "wall_s": dense.wall_s,
                  "r_star": float(dense.r[i]), "E_hard": float(dense.E_hard[i])},
        "basin_check": solve.basin_check(dense, s.r_star, s.E_hard_star, s.bracket)
        or "r* lies in the basin of the best dense point",
    }


def print_processes(rows: list[dict]) -> None:
    print(f"{'run':<34} {'wall s':>8} {'compile s':>10} {'run s':>8} {'compiled':>9} {'lowered':>8} "
          f"{'r* deg':>8} {'E_hard m':>9}")
    for row in rows:
        lowered = "-" if row["programs_lowered"] is None else str(row["programs_lowered"])
        print(f"{row['run']:<34} {row['wall_s']:8.1f} {row['compile_s']:10.1f} {row['run_s']:8.1f} "
              f"{row['programs_compiled']:>9} {lowered:>8} {row['r_star']:8.2f} {row['E_hard_star']:9.4f}")


def print_solve_against_dense(out: dict) -> None:
    s, d = out["solve"], out["dense"]
    print(f"{'method':<30} {'evaluations':>11} {'programs':>8} {'wall s':>8} {'r* deg':>8} {'E_hard m':>9}")
    print(f"{'sweep + continuous solve':<30} {s['evaluations']:>11} {s['programs']:>8} {s['wall_s']:8.2f} "
          f"{s['r_star']:8.2f} {s['E_hard']:9.4f}")
    label = f"dense grid, {d['step']:g} deg"
    print(f"{label:<30} {d['evaluations']:>11} {d['evaluations']:>8} {d['wall_s']:8.2f} "
          f"{d['r_star']:8.2f} {d['E_hard']:9.4f}")
    print(f"wall-time ratio dense / continuous: {d['wall_s'] / s['wall_s']:.1f}x; "
          f"E_hard continuous - dense: {s['E_hard'] - d['E_hard']:+.4f} m")
    print("basin check: " + out["basin_check"])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", default=None, help="predictor weights (default: the shipped ones)")
    p.add_argument("--variants", type=int, default=8)
    p.add_argument("--scenarios", default=None, help="comma-separated (default: the config's six)")
    p.add_argument("--skip-cold", action="store_true", help="skip part 1 (the fresh processes)")
    p.add_argument("--processes-only", action="store_true", help="part 1 only")
    p.add_argument("--repeat", type=int, default=1, help="warm processes after the cold one (default 1)")
    p.add_argument("--python", default=sys.executable,
                   help="interpreter whose installed diffsense the processes of part 1 run (default: this one)")
    p.add_argument("--flags", default="", help='more options of the timed command, e.g. "--predictor-dtype bfloat16"')
    p.add_argument("--dense-step", type=float, default=0.5, help="spacing of part 2's dense grid [deg]")
    p.add_argument("--json", type=Path, default=None, help="also write every measured number to this file")
    args = p.parse_args()
    if args.skip_cold and args.processes_only:
        p.error("--skip-cold and --processes-only leave nothing to run")
    print(f"jax {jax.__version__} on {jax.default_backend()}, {os.cpu_count()} CPU cores, "
          f"{platform.processor() or platform.machine()}, variants per scenario {args.variants}"
          + (f", scenarios {args.scenarios}" if args.scenarios else ""))
    measured: dict = {"variants": args.variants, "scenarios": args.scenarios, "flags": args.flags}

    if not args.skip_cold:
        where = subprocess.run([args.python, "-c", "import importlib.util as u, pathlib; print(pathlib.Path(u.find_spec('diffsense').origin).parents[1])"],
                               capture_output=True, text=True, check=True, timeout=300).stdout.strip()
        measured["repo"] = f"{args.python}: {_describe(Path(where))}"
        print(f"\n1. the default command in a fresh process, diffsense from {measured['repo']}")
        measured["processes"] = cold_and_warm(args.model, args.variants, args.scenarios, args.repeat, args.python,
                                              args.flags)
        print_processes(measured["processes"])

    if not args.processes_only:
        import diffsense as ds
        from diffsense import cli

        cli.setup_jax(float64=True, compilation_cache=False)
        predictor = ds.predictors.load_predictor(args.model)
        scenarios = {"scenarios": args.scenarios} if args.scenarios else {}
        problem = ds.Problem.from_toml(None, variants=args.variants, **scenarios)
        E, measured["solve_vs_dense"] = solve_against_dense(problem, predictor, args.dense_step)
        print(f"\n2. continuous solve versus the dense {args.dense_step:g}-deg hard grid (same objective, compiled)")
        print_solve_against_dense(measured["solve_vs_dense"])

        print("\n3. far background traffic (100 vehicles per scenario)")
        bg_problem = ds.Problem.from_toml(None, variants=args.variants, background_vehicles=100, **scenarios)
        bg = build_and_search(bg_problem, predictor)
        # The two searches in turn, three times each, medians: one timing each was at the mercy of
        # whatever the machine did at that moment (a first one at 5.6 s, a later one at 3.8 s).
        pairs = [(timed_search(problem, E)[1], timed_search(bg_problem, bg)[1]) for _ in range(3)]
        solve_s, bg_s = (float(np.median(column)) for column in zip(*pairs))
        measured["background"] = {"vehicles_kept": int(E.data.scenes.num_vehicles), "wall_s": solve_s,
                                  "vehicles_kept_with_100": int(bg.data.scenes.num_vehicles), "wall_s_with_100": bg_s}
        print(f"{'scene':<26} {'V kept':>7} {'solve wall s':>13}")
        print(f"{'paper scenarios':<26} {E.data.scenes.num_vehicles:>7} {solve_s:13.2f}")
        print(f"{'+100 background each':<26} {bg.data.scenes.num_vehicles:>7} {bg_s:13.2f}")
        print(f"run-time change: {100 * (bg_s / solve_s - 1):+.1f} % (target: under 20 %)")
    if args.json:
        args.json.write_text(json.dumps(measured, indent=1) + "\n")


if __name__ == "__main__":
    main()
