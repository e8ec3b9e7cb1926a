"""`python -m diffsense.optimise`: the best sensor parameter r over an interval.

    python -m diffsense.optimise --param hfov --interval 30 180

Simulates the paper's six scenarios (8 variants each), models the radar (or camera) with the
parameter free, predicts with the shipped CS-LSTM, runs the paper's stepped sweep with hard
detections and the continuous solve with soft ones, and writes result.json, objective.png,
rmse_horizon.png and detections.png to --out. Every default lives in
configs/optimise/default.toml; every flag overrides one of them.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from diffsense import cli as _cli
from diffsense import config as cfgio
from diffsense.errors import InputError
from diffsense.metrics import ProblemConfig
from diffsense.solve import SolveConfig

SENSOR_CHOICES = ("radar", "camera", "both")


@dataclasses.dataclass(frozen=True)
class RadarIntervals:
    hfov_deg: tuple[float, float]
    vfov_deg: tuple[float, float]
    range_m: tuple[float, float]
    tx_power_dbm: tuple[float, float]
    noise_figure_db: tuple[float, float]


@dataclasses.dataclass(frozen=True)
class CameraIntervals:
    hfov_deg: tuple[float, float]
    range_m: tuple[float, float]
    width_px: tuple[float, float]
    baseline_m: tuple[float, float]


@dataclasses.dataclass(frozen=True)
class Intervals:
    radar: RadarIntervals
    camera: CameraIntervals


@dataclasses.dataclass(frozen=True)
class PlotsConfig:
    """extra_curve_points: evenly spaced E(r) evaluations drawn in objective.png beyond the
    sweep steps and r* (each costs one soft value-and-gradient and one hard evaluation) [-]."""

    extra_curve_points: int = 0

    def __post_init__(self):
        if not 0 <= self.extra_curve_points <= 1000:
            raise InputError(f"plots.extra_curve_points must be in [0, 1000], got {self.extra_curve_points}")


@dataclasses.dataclass(frozen=True)
class OptimiseConfig:
    """configs/optimise/default.toml."""

    problem: ProblemConfig
    solve: SolveConfig
    plots: PlotsConfig
    intervals: Intervals


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m diffsense.optimise",
        description="Find the sensor parameter r in [LO, HI] that minimises the trajectory "
        "prediction error E_RMSE(r) (the paper's Eq. 12), cross-checked by the stepped sweep.",
    )
    p.add_argument("--config", help="TOML with the keys of configs/optimise/default.toml")
    p.add_argument("--sensor", choices=SENSOR_CHOICES, help="sensor (both: radar and camera, compared)")
    p.add_argument("--param", help="differentiable sensor parameter, e.g. hfov, range, tx_power, width")
    p.add_argument("--interval", nargs=2, type=float, metavar=("LO", "HI"), help="interval of r (parameter units)")
    p.add_argument("--steps", help="comma-separated sweep steps (default: the paper's for hfov)")
    p.add_argument("--scenarios", help="comma-separated scenario names or TOML paths")
    p.add_argument("--variants", type=int, help="variants per scenario")
    p.add_argument("--model", help="predictor weights (.msgpack of this project or a PyTorch checkpoint)")
    p.add_argument("--fill", choices=("zero", "hold", "interp"), help="missing-detection policy")
    p.add_argument("--estimator", choices=("mean-field", "mc", "hard"), help="how detection uncertainty enters")
    p.add_argument("--mc-samples", type=int, help="Monte-Carlo samples K (--estimator mc)")
    p.add_argument("--tau", type=float, help="temperature multiplier of the final continuation level")
    p.add_argument("--seed", type=int, help="seed of scenes, noise and Monte-Carlo draws")
    p.add_argument("--dense-check", type=float, metavar="STEP",
                   help="also evaluate E_hard every STEP (parameter units, e.g. 0.5 deg) over the "
                   "interval and report whether r* lies in the basin of the best dense point")
    p.add_argument("--out", default="out", help="output folder (default: out)")
    p.add_argument("--quiet", action="store_true", help="print only the summary table")
    return p


def _number_list(text: str, what: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise InputError(f"{what} must be comma-separated numbers, got {text!r}") from None
    if not values or not all(math.isfinite(v) for v in values):
        raise InputError(f"{what} must be finite numbers, got {text!r}")
    return values


def _load_config(args: argparse.Namespace):
    if args.config:
        cfg = cfgio.load(OptimiseConfig, args.config)
    else:
        cfg = cfgio.load_default(OptimiseConfig, "optimise/default.toml")
    problem: dict[str, Any] = cfgio.to_dict(cfg.problem)
    if args.sensor and args.sensor != "both":
        problem["sensor"] = args.sensor
    if args.param:
        problem["param"] = args.param
    if args.scenarios:
        problem["scenarios"] = tuple(s.strip() for s in args.scenarios.split(",") if s.strip())
    for flag in ("variants", "model", "fill", "seed"):
        if getattr(args, flag) is not None:
            problem[flag] = getattr(args, flag)
    estimator = cfgio.to_dict(cfg.problem.estimator)
    if args.estimator:
        estimator["kind"] = args.estimator
    if args.mc_samples is not None:
        estimator["samples"] = args.mc_samples
    problem["estimator"] = estimator
    solve = cfgio.to_dict(cfg.solve)
    if args.tau is not None:
        if not (math.isfinite(args.tau) and args.tau > 0):
            raise InputError(f"--tau must be a positive number, got {args.tau}")
        # The continuation keeps its shape and ends at the requested temperature.
        last = solve["tau_schedule"][-1]
        solve["tau_schedule"] = [t * args.tau / last for t in solve["tau_schedule"]]
    return cfgio.replace(cfg, problem=problem, solve=solve)


class _Progress:
    def __init__(self, quiet: bool):
        self.quiet = quiet
        self.t0 = time.perf_counter()

    def __call__(self, message: str) -> None:
        if not self.quiet:
            print(f"[{time.perf_counter() - self.t0:6.1f} s] {message}", file=sys.stderr, flush=True)


def _sensors(args: argparse.Namespace, cfg) -> list[str]:
    return ["radar", "camera"] if args.sensor == "both" else [cfg.problem.sensor]


def _interval(args, cfg, sensor: str, spec) -> tuple[float, float]:
    from diffsense.metrics import check_interval

    if args.interval is not None:
        lo, hi = args.interval
    else:
        lo, hi = getattr(getattr(cfg.intervals, sensor), spec.name)
    check_interval(spec, lo, hi)
    return float(lo), float(hi)


def _check_dense_step(step: float | None, intervals: list[tuple[float, float]]) -> None:
    if step is None:
        return
    if not (math.isfinite(step) and step > 0):
        raise InputError(f"--dense-check must be a positive step, got {step}")
    for lo, hi in intervals:
        if (hi - lo) / step > 100_000:
            raise InputError(f"--dense-check {step:g} makes over 100,000 points on [{lo:g}, {hi:g}]")


def _dense_check(obj, result, lo: float, hi: float, step: float) -> dict[str, Any]:
    """E_hard on a dense grid and the basin check of r* (issue: r* in the best dense basin)."""
    from diffsense.solve import basin_check, dense_grid_search

    dense = dense_grid_search(obj.e_hard, (lo, hi), step)
    why = basin_check(dense, result.r_star, result.E_hard_star, result.bracket)
    i = dense.best_index
    return {
        "step": step, "evaluations": dense.evaluations, "wall_s": dense.wall_s,
        "r_best": float(dense.r[i]), "E_hard_best": float(dense.E_hard[i]),
        "basin": list(dense.basin()), "in_basin": why is None,
        "E_hard_star_minus_best": result.E_hard_star - float(dense.E_hard[i]),
        "verdict": why or f"r* lies in the basin {list(dense.basin())} of the best dense point "
                          f"r={float(dense.r[i]):.6g}",
    }


def _run_one(sensor: str, args, cfg, out: Path, progress: _Progress, predictor) -> dict[str, Any]:
    from diffsense import report
    from diffsense._timing import CompileClock
    from diffsense.metrics import build_problem, resolve_param
    from diffsense.scene import ROLE_NAMES
    from diffsense.solve import hard_grid_solve, solve

    problem_cfg = cfgio.replace(cfg.problem, sensor=sensor)
    spec = resolve_param(sensor, problem_cfg.param)
    lo, hi = _interval(args, cfg, sensor, spec)
    steps = _number_list(args.steps, "--steps") if args.steps else None
    hard_only = problem_cfg.estimator.kind == "hard"
    progress(f"{sensor}: simulating {len(problem_cfg.scenarios)} scenarios x {problem_cfg.variants} variants; "
             "ground-truth predictions")
    with CompileClock() as clock:
        problem = build_problem(problem_cfg, predictor=predictor)
        obj = problem.objective
        progress(f"{sensor}: stepped sweep and {'hard grid' if hard_only else 'continuous solve'} "
                 f"of {spec.name} over [{lo:g}, {hi:g}] {spec.unit}")
        if hard_only:
            result = hard_grid_solve(obj.e_hard, (lo, hi), steps=steps, max_evaluations=cfg.solve.max_evaluations)
        else:
            e2_soft, e_hard = obj.solver_fns(jnp.float64 if cfg.solve.dtype == "float64" else jnp.float32)
            result = solve(e2_soft, e_hard, (lo, hi), steps=steps, config=cfg.solve)
        solve_counts = dict(obj.counts)
        progress(f"{sensor}: r* = {result.r_star:.5g} {spec.unit}, E_hard(r*) = {result.E_hard_star:.4f} m; "
                 "figures")
        # The figures reuse every evaluation the solve made (the objective memoises them).
        tau = result.tau_schedule[-1] if result.tau_schedule else 1.0
        extra = np.linspace(lo, hi, cfg.plots.extra_curve_points) if cfg.plots.extra_curve_points else []
        r_curve = sorted({p.r for p in result.sweep} | {result.r_star} | {float(r) for r in extra})
        soft_curve, grad_curve, hard_curve = [], [], []
        for r in r_curve:
            e2, g = (obj.e_hard(r) ** 2, 0.0) if hard_only else obj.value_and_grad(r, tau)
            e = math.sqrt(max(e2, 0.0))
            soft_curve.append(e)
            grad_curve.append(g / (2 * e) if e > 0 else 0.0)  # dE/dr = dE^2/dr / (2E)
            hard_curve.append(obj.e_hard(r))
        curves: dict[str, dict[str, Any]] = {}
        for r in [p.r for p in result.sweep]:
            gt, sens = obj.horizon_rmse(r)
            for s_i, name in enumerate(problem.scenario_names):
                curves.setdefault(name, {"gt": gt[s_i], "steps": {}})["steps"][r] = sens[s_i]
        timeline_r = sorted({lo, result.r_star, hi})
        first = jax.tree.map(lambda a: a[0], obj.data.scenes)  # nominal variant of the first scenario
        det = {r: np.asarray(obj.detections(r, mode="hard").p_detect[0]) for r in timeline_r}
        present = np.asarray(first.present)
        cols = [v for v in range(1, present.size) if present[v]]  # the ego always knows itself
        roles = [ROLE_NAMES[int(first.role[v])] for v in cols]
    plot_counts = {k: obj.counts[k] - solve_counts[k] for k in obj.counts}
    extra: dict[str, Any] = {}
    if args.dense_check is not None:
        progress(f"{sensor}: dense hard grid every {args.dense_check:g} {spec.unit} (--dense-check)")
        extra["dense_check"] = _dense_check(obj, result, lo, hi, args.dense_check)
        result = dataclasses.replace(result, notes=(*result.notes, "dense check: " + extra["dense_check"]["verdict"]))
    content = report.result_dict(
        result, param=spec.name, sensor=sensor, r_unit=spec.unit,
        wall_s={"compile": clock.compile_s, "run": clock.run_s},
        config=cfgio.to_dict(cfg) | {"interval": [lo, hi], "steps": list(steps) if steps else None},
        extra={"objective_programs_run": solve_counts, "plot_programs_run": plot_counts,
               "scenarios": problem.scenario_names, "unit": spec.unit} | extra,
    )
    out.mkdir(parents=True, exist_ok=True)
    report.write_result_json(out / "result.json", content)
    report.plot_objective(out / "objective.png", r_curve, soft_curve, hard_curve, grad_curve,
                          [dataclasses.asdict(p) for p in result.sweep], result.r_star,
                          param=spec.name, unit=spec.unit)
    report.plot_rmse_horizon(out / "rmse_horizon.png", curves, param=spec.name, unit=spec.unit)
    report.plot_detection_timeline(out / "detections.png", {r: det[r][:, cols] for r in timeline_r}, roles,
                                   dt_s=first.dt_s, param=spec.name, unit=spec.unit)
    progress(f"{sensor}: wrote {out}/result.json, objective.png, rmse_horizon.png, detections.png")
    return content


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    cfg = _load_config(args)
    sensors = _sensors(args, cfg)
    from diffsense.metrics import resolve_param

    for sensor in sensors:  # validate every input before any work or any file
        _interval(args, cfg, sensor, resolve_param(sensor, cfg.problem.param))
    if args.steps:
        _number_list(args.steps, "--steps")
    _check_dense_step(args.dense_check, [_interval(args, cfg, s, resolve_param(s, cfg.problem.param))
                                         for s in sensors])
    from diffsense.scene import load_scenario

    for name in cfg.problem.scenarios:
        load_scenario(name)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out} exists and is not a folder")

    _cli.setup_jax(float64=cfg.problem.float64)
    from diffsense import report
    from diffsense.predictors import load_predictor

    progress = _Progress(args.quiet)
    predictor = load_predictor(cfg.problem.model or None)  # a bad checkpoint fails before any output
    progress("loaded the predictor" + (f" {cfg.problem.model}" if cfg.problem.model else " (shipped weights)"))
    results = {}
    for sensor in sensors:
        folder = out / sensor if len(sensors) > 1 else out
        results[sensor] = _run_one(sensor, args, cfg, folder, progress, predictor)
    for sensor, content in results.items():
        print("\n" + report.summary_table(content, unit=content["unit"]))
    if len(results) > 1:
        table = report.comparison_table(results, unit=results[sensors[0]]["unit"])
        print("\nradar versus camera\n" + table)
        from diffsense._io import write_bytes

        write_bytes(out / "comparison.txt", (table + "\n").encode())
    return 0


def console() -> None:
    """The `diffsense-optimise` console script: `main` under the error contract of `run`."""
    _cli.run(main)
