"""The main job's flags and `--config` (or `--suite`) made into `diffsense.Problem`s, one per
sensor asked for, every input checked before any computation."""

from __future__ import annotations

import argparse
import dataclasses
import math

from diffsense.cli._suite import suite_fields
from diffsense.runtime import InputError


def _param_boxes(params: list[str] | None) -> dict[str, tuple[float, float]]:
    """{name: (lo, hi)} from repeated --param NAME=LO:HI ({} for the single-name form)."""
    if not params or (len(params) == 1 and "=" not in params[0]):
        return {}
    boxes: dict[str, tuple[float, float]] = {}
    for text in params:
        name, eq, bounds = text.partition("=")
        lo, colon, hi = bounds.partition(":")
        if not (eq and colon and name.strip()):
            raise InputError(f"--param {text!r}: give NAME=LO:HI when naming several parameters")
        try:
            pair = (float(lo), float(hi))
        except ValueError:
            raise InputError(f"--param {text!r}: LO and HI must be numbers") from None
        if name.strip() in boxes:
            raise InputError(f"parameter {name.strip()} is named twice")
        boxes[name.strip()] = pair
    return boxes


def _number_list(text: str, what: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise InputError(f"{what} must be comma-separated numbers, got {text!r}") from None
    if not values or not all(math.isfinite(v) for v in values):
        raise InputError(f"{what} must be finite numbers, got {text!r}")
    return values


def _sensors(text: str) -> list:
    """The sensor of each problem --sensor asks for: "both" is two, "radar,camera" one suite."""
    if text == "both":
        return ["radar", "camera"]
    if "," in text:
        return [tuple(s.strip() for s in text.split(",") if s.strip())]
    return [text]


def _suite_sensor(sensor: list | dict) -> tuple | dict:
    """A suite file's sensor: its kinds as a suite (a tuple), or its named members (a mapping)."""
    return tuple(sensor) if isinstance(sensor, list) else sensor


def problems(args: argparse.Namespace) -> list:
    """The `diffsense.Problem` of each sensor the flags ask for, every input checked."""
    from diffsense.solve import check_steps
    from diffsense.study import (
        Problem,
        checked,
        load_settings,
        problem_fields,
        shared_fields,
    )

    settings = load_settings(args.config)
    suite = suite_fields(args)
    sensors = [_suite_sensor(suite["sensor"])] if suite else _sensors(args.sensor or settings.problem.sensor)
    boxes = _param_boxes(args.param) or (suite["params"] if suite else {})
    if boxes and args.interval:
        raise InputError("--param NAME=LO:HI carries its bounds: give no --interval with it")
    single = None if boxes or not args.param else args.param[0]
    out = []
    for sensor in sensors:
        if boxes or not isinstance(sensor, str):
            if not boxes:
                raise InputError("a suite needs its parameters as --param NAME=LO:HI (e.g. radar.hfov_deg=20:120)")
            fields = dict(sensor=sensor, params=boxes, **shared_fields(settings))  # the config's param is not theirs
        else:
            fields = problem_fields(settings, sensor, single, tuple(args.interval) if args.interval else None)
        fields.update(_flag_fields(args, settings, suite))
        problem = checked(args.suite, lambda: Problem(**fields)) if suite else Problem(**fields)
        if problem.solver.steps is not None:
            (lo, hi), = problem.params.values()
            check_steps(problem.solver.steps, lo, hi)
        out.append(problem)
    return out


def _flag_fields(args: argparse.Namespace, settings, suite: dict | None) -> dict:
    """The `Problem` fields the flags set over the config's (every sensor's problem alike)."""
    from diffsense.config import to_dict
    from diffsense.metrics import EstimatorConfig
    from diffsense.solve import BoxConfig

    fields: dict = {}
    if suite:
        fields["cost_weight"] = suite["cost_weight"]
        if "sensor_config" in suite:
            fields["sensor_config"] = suite["sensor_config"]
    if args.cost_weight is not None:
        fields["cost_weight"] = args.cost_weight
    if args.scenarios is not None and args.scenes is not None:  # else the scenarios pass unread
        raise InputError("--scenarios and --scenes exclude each other: recorded scenes replace the scenarios")
    if args.scenarios is not None:
        fields["scenarios"] = args.scenarios
    if args.scenes is not None:
        fields["scenes"] = args.scenes
    for flag, key in (("variants", "variants"), ("model", "predictor"), ("fill", "fill"), ("seed", "seed"),
                      ("objective", "objective"), ("miss_penalty", "miss_penalty_m2"), ("predictor_dtype", "predictor_dtype"),
                      ("profile", "profile"), ("sensor_config", "sensor_config"),
                      ("traffic_speed_offset_kmh", "traffic_speed_offset_kmh"), ("window_s", "window_s"),
                      ("crossing_at_s", "crossing_at_s"), ("target_ci", "target_ci")):
        if getattr(args, flag) is not None:
            fields[key] = getattr(args, flag)
    estimator = to_dict(settings.problem.estimator)
    if args.estimator:
        estimator["kind"] = args.estimator
    if args.mc_samples is not None:
        estimator["samples"] = args.mc_samples
    if args.draws is not None:
        estimator["reference_draws"] = args.draws
    if args.gradient_draws is not None:
        estimator["gradient_draws"] = args.gradient_draws
    fields["estimator"] = EstimatorConfig(**estimator)
    if args.tau is not None:
        if not (math.isfinite(args.tau) and args.tau > 0):
            raise InputError(f"--tau must be a positive number, got {args.tau}")
        # The continuation keeps its shape and ends at the requested temperature.
        taus = settings.solve.tau_schedule
        fields["solve"] = dataclasses.replace(settings.solve, tau_schedule=tuple(t * args.tau / taus[-1] for t in taus))
    if args.steps:
        fields["steps"] = _number_list(args.steps, "--steps")
    fields["dense_check"] = args.dense_check
    if getattr(args, "r_star_axes", False):
        fields["box"] = BoxConfig(r_star_axes=True)
    weather = {k: v for k, v in (("rain_mm_h", args.rain_mm_h), ("fog_visibility_m", args.fog_visibility_m))
               if v is not None}
    if weather:
        fields["weather"] = weather
    return fields
