"""`diffsense optimise` (and `python -m diffsense.optimise`): the best sensor parameter r over an interval.

    diffsense optimise --param hfov --interval 30 180

A thin face over `diffsense.optimise`: the flags and `--config` become a `diffsense.Problem`
(defaults: configs/optimise/default.toml; a config file may be partial), the library solves it,
and result.json, objective.png, rmse_horizon.png and detections.png are written to --out
(with `--sensor both`, one folder per sensor, each result.json's comparisons holding the paired
radar-versus-camera difference with its interval, and comparison.txt; with --pareto, pareto.json and
pareto.png). --suite FILE reads the sensors, parameters and cost weight from a suite file.
"""

from __future__ import annotations

import argparse
import atexit
import importlib
import math
import os
import shutil
import tempfile
import threading
from pathlib import Path

import diffsense as ds
from diffsense import runtime
from diffsense.cli import Parser, Progress, run, setup_jax
from diffsense.cli._problems import problems
from diffsense.cli._suite import pareto_lambdas, pareto_run
from diffsense.metrics import ESTIMATORS
from diffsense.predictors import load_predictor
from diffsense.runtime import InputError
from diffsense.scene import check_speed_offset, load_scenario
from diffsense.study import ODD_PARAMETERS, check_theta, memory_estimate_bytes, recorded_cut, with_modality_comparisons

PROG = "python -m diffsense.optimise"


def _parser(prog: str = PROG) -> argparse.ArgumentParser:
    p = Parser(
        prog=prog,
        description="Find the sensor parameter r in [LO, HI] that minimises the trajectory "
        "prediction error E_RMSE(r) (the paper's Eq. 12), cross-checked by the stepped sweep.",
    )
    p.add_argument("--config", help="TOML with keys of configs/optimise/default.toml (the rest keep their defaults)")
    p.add_argument("--sensor", help="radar, camera, both (each alone, compared) or a suite fused into one "
                   "track per vehicle: radar,camera")
    p.add_argument("--param", action="append", metavar="NAME[=LO:HI]",
                   help="differentiable parameter, e.g. hfov, range, tx_power, width (with --interval); or, "
                   "repeated, NAME=LO:HI for several at once (a suite's are qualified: radar.hfov_deg=20:120)")
    p.add_argument("--suite", metavar="FILE", help="a suite file (configs/suites/*.toml): the sensors, their free "
                   "parameters with bounds and the cost weight, instead of --sensor and --param")
    p.add_argument("--pareto", nargs="?", const="", metavar="LAMBDAS",
                   help="trace the E-versus-cost front instead of one solve: a box solve per cost weight, each "
                   "warm-started from the last (comma-separated, m per currency unit; default "
                   "0,0.001,0.002,0.005,0.01,0.02,0.05); writes pareto.json and pareto.png")
    p.add_argument("--cost-weight", type=float, metavar="LAMBDA",
                   help="optimise E + LAMBDA * cost (configs/costs.toml) [m per currency unit]")
    p.add_argument("--interval", nargs=2, type=float, metavar=("LO", "HI"), help="interval of r (parameter units)")
    p.add_argument("--steps", help="comma-separated sweep steps (default: the paper's for hfov)")
    p.add_argument("--scenarios", help="comma-separated scenario names or TOML paths")
    p.add_argument("--scenes", metavar="KIND:PATH",
                   help="recorded traffic instead of scenarios (not with --scenarios): highd:NN_tracks.csv or "
                   "ngsim:TRAJECTORIES.csv")
    p.add_argument("--window-s", type=float, metavar="S",
                   help="with --scenes: the window cut around each lane change [s] (default 10: the predictor's "
                   "3 s history + 5 s future + 2 s of prediction instants)")
    p.add_argument("--crossing-at-s", type=float, metavar="S",
                   help="with --scenes: where in the window the lane change crosses the marking [s from its start] "
                   "(default: each window placed to fit the recording)")
    p.add_argument("--variants", type=int, help="variants per scenario")
    p.add_argument("--target-ci", type=float, metavar="M",
                   help="double the variants (from --variants, up to 128) until the decision's interval (best against "
                   "second-best step) has a half-width under M metres or excludes 0; result.json's target_ci says how many")
    p.add_argument("--r-star-axes", action="store_true",
                   help="a many-parameter answer: also r*'s interval per parameter, along its axis through r* "
                   "(up to 25 evaluations of E per parameter)")
    p.add_argument("--model", help="predictor weights (.msgpack of this project or a PyTorch checkpoint)")
    p.add_argument("--profile", choices=("physical", "paper"),
                   help="the sensors' shipped constants: physical (default) or paper (the paper's design)")
    p.add_argument("--sensor-config", metavar="FILE", help="TOML of sensor constants (any subset) replacing the profile's")
    p.add_argument("--fill", choices=("zero", "hold", "interp"), help="missing-detection policy (default: the profile's)")
    p.add_argument("--predictor-dtype", choices=("auto", "float32", "float64", "bfloat16"),
                   help="the predictor's arithmetic inside the float64 E(r) (default auto: the CS-LSTM in float32, "
                        "its weights' own precision, at half the cost; bfloat16: float32 with the LSTM products on "
                        "bfloat16 operands, faster again; docs: speed and accuracy)")
    p.add_argument("--estimator", choices=ESTIMATORS,
                   help="how detection uncertainty enters (auto, under a probabilistic detection law: straight-through "
                        "for one parameter, relaxed-reference for several; mean-field under the threshold law; "
                        "docs: detection)")
    p.add_argument("--mc-samples", type=int, help="Monte-Carlo samples K (--estimator mc)")
    p.add_argument("--draws", type=int, metavar="K",
                   help="detection draws K of the reference E_ref a probabilistic law is answered on "
                        "(default 32; each costs a predictor pass per evaluation; docs: detection)")
    p.add_argument("--gradient-draws", type=int, metavar="KG",
                   help="of those, the first KG are relaxed for the gradient (default 8: a mini-batch; "
                        "answers stay on all K; docs: detection)")
    p.add_argument("--objective", choices=("eq12", "tracked"),
                   help="eq12: the paper's E over every instant; tracked: the error where the target has a "
                   "track plus --miss-penalty per missed share")
    p.add_argument("--miss-penalty", type=float, metavar="M2",
                   help="tracked: price of an instant without a track [m^2] (default 100: a 10 m RMS error)")
    p.add_argument("--tau", type=float, help="temperature multiplier of the final continuation level")
    p.add_argument("--seed", type=int, help="seed of scenes, noise and Monte-Carlo draws")
    p.add_argument("--rain-mm-h", type=float, metavar="R", help="rain rate [mm/h] (radar attenuation, camera visibility)")
    p.add_argument("--fog-visibility-m", type=float, metavar="V", help="fog visibility [m] (camera contrast range)")
    p.add_argument("--sensitivity", metavar="THETA,...",
                   help="ODD parameters whose dr*/dtheta to report: rain_mm_h, fog_visibility_m, "
                   "traffic_speed_kmh (simulated scenarios only)")
    p.add_argument("--traffic-speed-offset-kmh", type=float, metavar="KMH",
                   help="added to every vehicle's start speed in the scenarios [km/h] (default 0)")
    p.add_argument("--dense-check", type=float, metavar="STEP",
                   help="also evaluate the reference E_ref (E_hard under the deterministic threshold law; "
                   "its expectation over detection draws, with standard errors, under a probabilistic one) "
                   "every STEP (parameter units, e.g. 0.5 deg) over the interval and report whether r* "
                   "lies in the basin of the best dense point")
    p.add_argument("--max-memory-gb", type=float, default=None,
                   help="refuse a run whose estimated memory exceeds this (default: half the machine's memory)")
    p.add_argument("--distributed", action="store_true",
                   help="join a multi-process run (one process per host; variants sharded over all devices); "
                        "process 0 writes the outputs; the join waits at most DIFFSENSE_JOIN_TIMEOUT_S s (default 60)")
    p.add_argument("--coordinator", metavar="HOST:PORT", help="process 0's address (else JAX_COORDINATOR_ADDRESS "
                   "or the scheduler's)")
    p.add_argument("--num-processes", type=int, metavar="N", help="processes in the run (else JAX_NUM_PROCESSES)")
    p.add_argument("--process-id", type=int, metavar="I", help="this process's id, 0..N-1 (else JAX_PROCESS_ID)")
    p.add_argument("--out", default="out", help="output folder (default: out)")
    p.add_argument("--quiet", action="store_true", help="print only the summary table")
    return p


def _check_inputs(problems_: list) -> None:
    """Every input that can be checked before any computation: scenarios, a recording (read and
    cut here, before JAX starts: the run takes the same cut), predictor file."""
    for problem in problems_:
        traffic, model = problem.traffic, problem.prediction.predictor
        recorded_cut(problem)
        for name in () if traffic.scenes is not None else traffic.scenarios:
            check_speed_offset(load_scenario(name), traffic.traffic_speed_offset_kmh)
        if isinstance(model, str) and model and not Path(model).is_file():
            raise InputError(f"--model {model}: not a file")


def _sensitivity_names(text: str | None, problems_: list) -> tuple[str, ...]:
    names = tuple(t.strip() for t in (text or "").split(",") if t.strip())
    unknown = [t for t in names if t not in ODD_PARAMETERS]
    if unknown:
        raise InputError(f"--sensitivity: no sensitivity to {unknown[0]!r} (known: {', '.join(ODD_PARAMETERS)})")
    for problem in problems_:
        check_theta(problem, names)
    return names


def _check_memory(todo: list, max_memory_gb: float | None) -> None:
    """Refuse, before any computation, a run whose estimated memory exceeds the limit."""
    if max_memory_gb is None:
        limit = 0.5 * os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    elif math.isfinite(max_memory_gb) and max_memory_gb > 0:
        limit = max_memory_gb * 1e9
    else:
        raise InputError(f"--max-memory-gb must be a positive number, got {max_memory_gb}")
    need = max(memory_estimate_bytes(p) for p in todo)
    if need > limit:
        raise InputError(f"the run needs an estimated {need / 1e9:.1f} GB for its fixed data, over the limit of "
                         f"{limit / 1e9:.1f} GB (fewer variants or Monte-Carlo samples, or --max-memory-gb)")


def _join(args, out: Path) -> tuple[Path, bool]:
    """Join the distributed run; a process other than 0 computes the same steps but writes its
    outputs to a scratch folder and prints nothing. Returns (output folder, quiet)."""
    runtime.initialize(args.coordinator, args.num_processes, args.process_id)
    if runtime.is_writer():
        return out, args.quiet
    scratch = Path(tempfile.mkdtemp(prefix="diffsense-worker-"))
    atexit.register(shutil.rmtree, scratch, True)
    return scratch, True


def main(argv: list[str] | None = None, prog: str = PROG) -> int:
    args = _parser(prog).parse_args(argv)
    if not args.distributed and (args.coordinator, args.num_processes, args.process_id) != (None, None, None):
        raise InputError("--coordinator, --num-processes and --process-id need --distributed")
    todo = problems(args)
    lambdas = pareto_lambdas(args, todo)
    _check_inputs(todo)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out} exists and is not a folder")
    theta = _sensitivity_names(args.sensitivity, todo)
    runtime.check_writable(out)  # before any computation
    _check_memory(todo, args.max_memory_gb)

    setup_jax(float64=todo[0].prediction.float64)
    if args.distributed:
        out, args.quiet = _join(args, out)
    # Start-up: diffsense.report (matplotlib's figures) is imported in the background, while
    # the computations, which release the GIL, run.
    threading.Thread(target=importlib.import_module, args=("diffsense.report",), daemon=True).start()

    progress = Progress(args.quiet)
    model = todo[0].prediction.predictor
    predictor = load_predictor(model or None)  # a bad checkpoint fails before any output
    progress("loaded the predictor" + (f" {model}" if model else " (shipped weights)"))
    if lambdas is not None:
        return pareto_run(todo[0], lambdas, out, predictor, progress)
    results, solved = {}, {}
    comparison = None
    # Every file of the run is written to a staging folder and published into --out as one set:
    # an interrupted or failed run leaves the previous run's files as they were.
    with runtime.output_set(out) as staging:
        for problem in todo:
            solved[problem.sensor_kind] = ds.optimise(problem, predictor=predictor, progress=progress,
                                                      on_evaluation=progress.evaluation, sensitivity=theta)
        from diffsense import report  # imported in the background above (or waits for it)

        # radar against camera, paired over the scenes both saw: in each sensor's result.json
        for kind, result in with_modality_comparisons(solved).items():
            results[kind] = report.write_run(result, staging / kind if len(todo) > 1 else staging)
        if len(results) > 1:
            first = next(iter(results.values()))
            comparison = report.comparison_table(results, unit=first["units"][first["param"]])
            runtime.write_bytes(staging / "comparison.txt", (comparison + "\n").encode())
    progress(f"wrote {out}/: " + ", ".join(runtime.published_files(out)))
    if out == Path(args.out):  # else a distributed run's worker: process 0 prints and writes
        _print_tables(report, results, comparison)
    return 0


def _print_tables(report, results: dict, comparison: str | None) -> None:
    """Each sensor's summary (or box) table and breakdown, then the radar-camera comparison."""
    for content in results.values():
        if content["param"] is None:
            print("\n" + report.box_table(content))
        else:
            print("\n" + report.summary_table(content, unit=content["units"][content["param"]]))
        print(report.breakdown_table(content))
    if comparison is not None:
        print("\nradar versus camera\n" + comparison)


def console() -> None:
    """The `diffsense-optimise` console script: `main` under the error contract of `run`."""
    run(lambda: main(prog="diffsense-optimise"), end_process=True)
