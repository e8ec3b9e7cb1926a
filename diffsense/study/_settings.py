"""The TOML layout of an optimise config (`configs/optimise/default.toml`) and the `Problem`
keyword arguments it describes: what `Problem.from_toml` and the command line read."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from diffsense import config as cfgio
from diffsense.metrics import PAPER_SCENARIOS, EstimatorConfig
from diffsense.runtime import InputError
from diffsense.sensors import make_sensor, resolve_name
from diffsense.solve import SolveConfig


@dataclasses.dataclass(frozen=True)
class ProblemSection:
    """[problem] of an optimise config (see configs/optimise/default.toml for each key)."""

    sensor: str = "radar"
    param: str = "hfov_deg"
    scenarios: tuple[str, ...] = PAPER_SCENARIOS
    variants: int = 8
    model: str = ""
    profile: str = "physical"
    sensor_config: str = ""
    fill: str = ""
    estimator: EstimatorConfig = EstimatorConfig()
    seed: int = 0
    prediction_stride_frames: int = 4
    background_vehicles: int = 0
    float64: bool = True
    predictor_dtype: str = "auto"
    objective: str = "eq12"
    miss_penalty_m2: float = 100.0


@dataclasses.dataclass(frozen=True)
class PlotsSection:
    """[plots]: extra_curve_points, E(r) points drawn beyond the sweep steps and r* [-]."""

    extra_curve_points: int = 0


@dataclasses.dataclass(frozen=True)
class Settings:
    """A whole optimise config: the problem, the solver, the figures, the default intervals."""

    problem: ProblemSection = ProblemSection()
    solve: SolveConfig = SolveConfig()
    plots: PlotsSection = PlotsSection()
    intervals: dict[str, dict[str, tuple[float, float]]] = dataclasses.field(default_factory=dict)


def load_settings(path: str | Path | None = None) -> Settings:
    """The shipped optimise config, with the keys of the TOML at `path` (if any) replacing its."""
    return cfgio.load_layers(Settings, ["optimise/default.toml"], path)


def problem_fields(settings: Settings, sensor: str | None = None, param: str | None = None,
                   interval: tuple[float, float] | None = None) -> dict[str, Any]:
    """The `Problem` keyword arguments a config describes (sensor, param, interval overridable).

    The parameter's name is passed on as given, for `Problem` to resolve against its sensor;
    only a short name without an interval is resolved here, to find its [intervals] entry."""
    p = settings.problem
    sensor = sensor or p.sensor
    name = param or p.param
    if interval is None:
        table = settings.intervals.get(sensor, {})
        if name not in table:  # a short or qualified name: the table holds full names
            name = resolve_name(make_sensor(sensor), name)
        interval = table.get(name)
        if interval is None:
            raise InputError(f"no interval for {sensor} {name}: give one (--interval LO HI, or [intervals.{sensor}])")
    return dict(sensor=sensor, params={name: tuple(interval)}, **shared_fields(settings))


def shared_fields(settings: Settings) -> dict[str, Any]:
    """The `Problem` keyword arguments a config describes besides its sensor and parameter: what a
    suite or a box of parameters, which name their own, takes from it."""
    p = settings.problem
    return dict(scenarios=p.scenarios, variants=p.variants, seed=p.seed, predictor=p.model, fill=p.fill or None,
                estimator=p.estimator, profile=p.profile, sensor_config=p.sensor_config or None,
                prediction_stride_frames=p.prediction_stride_frames, background_vehicles=p.background_vehicles,
                float64=p.float64, predictor_dtype=p.predictor_dtype, objective=p.objective,
                miss_penalty_m2=p.miss_penalty_m2, solve=settings.solve, extra_curve_points=settings.plots.extra_curve_points)
