"""The suite flags of `python -m diffsense.optimise`: --suite FILE (with --param NAME=LO:HI replacing
its [params]) and --pareto [LAMBDAS]."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from diffsense.runtime import InputError


def suite_fields(args: argparse.Namespace) -> dict | None:
    """The fields of the suite file --suite names (None without one), refusing the flags it replaces.
    `--param NAME=LO:HI` (repeated) may replace the file's [params]: the same members with
    other free parameters (named as the file names them: front_radar.hfov_deg)."""
    if args.suite is None:
        return None
    single = bool(args.param) and len(args.param) == 1 and "=" not in args.param[0]
    given = [flag for flag, value in (("--sensor", args.sensor), ("--param", single),
                                      ("--interval", args.interval), ("--steps", args.steps)) if value]
    if given:
        hint = " (--param NAME=LO:HI replaces the file's [params])" if given[0] == "--param" else ""
        raise InputError(f"--suite names the sensors and parameters: give no {given[0]} with it{hint}")
    from diffsense.study import load_suite

    return load_suite(args.suite)


def pareto_lambdas(args: argparse.Namespace, problems: list) -> tuple[float, ...] | None:
    """The cost weights of --pareto (None without it), every conflicting flag refused."""
    if args.pareto is None:
        return None
    from diffsense.study import DEFAULT_LAMBDAS, check_lambdas

    if len(problems) != 1:
        raise InputError("--pareto traces one problem's front: give one sensor or a suite, not both")
    if args.sensitivity or args.dense_check is not None:
        raise InputError("--pareto takes no --sensitivity or --dense-check")
    if not args.pareto:
        return check_lambdas(DEFAULT_LAMBDAS)
    try:
        values = [float(v) for v in args.pareto.split(",") if v.strip()]
    except ValueError:
        raise InputError(f"--pareto must be comma-separated numbers, got {args.pareto!r}") from None
    return check_lambdas(values)


def pareto_run(problem: Any, lambdas: tuple[float, ...], out: Path, predictor: Any, progress: Any) -> int:
    """--pareto: the front of one problem, published as one output set (pareto.json, pareto.png),
    and its table printed."""
    import diffsense as ds
    from diffsense import report
    from diffsense.runtime import output_set, published_files

    with output_set(out) as staging:
        front = ds.pareto(problem, lambdas, predictor=predictor, progress=progress, on_evaluation=progress.evaluation)
        content = report.write_pareto(front, staging)
    progress(f"wrote {out}/: " + ", ".join(published_files(out)))
    print("\n" + report.pareto_table(content))
    return 0
