"""`Problem`: what to optimise (which sensor's named parameters, with bounds) and over what (scenes).

A Problem holds one small frozen spec per stage (`diffsense.study._specs`): `traffic`,
`sensing`, `prediction`, `question`, `solver`, and the `seed`. Building it simulates nothing;
it builds the sensor once (kept in `problem.sensing.built`). `diffsense.objective(problem)`
turns it into E(r); `diffsense.optimise(problem)` runs the main job on it.

    problem = Problem(sensor="radar", params={"hfov": (30, 180)}, scenarios=["sc01"], variants=2)
    problem.sensing.params              # {"hfov_deg": (30.0, 180.0)}: names resolved once
    problem.replace(variants=4)         # a new problem; the sensor is not built again
    Problem.from_specs(sensing=SensingSpec(sensor="camera"), traffic=TrafficSpec(variants=2))
    Problem(sensor={"front": "radar", "corner_left": {"kind": "radar", "yaw_deg": 45.0}},
            params={"corner_left.yaw_deg": (30, 80)})   # named members (`SensingSpec.sensor`)

`Problem.from_toml` reads the layout of `configs/optimise/default.toml`; a file may be partial,
and the keys it leaves out keep the shipped defaults.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from diffsense import config as cfgio
from diffsense.metrics import PAPER_SCENARIOS, EstimatorConfig
from diffsense.predictors import Predictor
from diffsense.runtime import InputError
from diffsense.scene import DEFAULT_WINDOW_S
from diffsense.sensors import Sensor
from diffsense.solve import BoxConfig, SolveConfig
from diffsense.study._settings import load_settings, problem_fields
from diffsense.study._specs import (
    CLEAR_WEATHER,
    PredictionSpec,
    QuestionSpec,
    SensingSpec,
    SolverSpec,
    TrafficSpec,
    check_int,
    profile_fill,
)
from diffsense.study._suite_file import checked, load_suite

MAX_SEED = 2**32 - 1

# Each flat keyword of `Problem(...)` and the spec that holds it (the seed is Problem's own).
STAGE_OF = {
    "sensor": "sensing", "params": "sensing", "scenarios": "traffic", "scenes": "traffic", "variants": "traffic",
    "seed": None, "predictor": "prediction", "profile": "sensing", "sensor_config": "sensing", "fill": "prediction",
    "estimator": "question", "prediction_stride_frames": "traffic", "background_vehicles": "traffic",
    "float64": "prediction", "predictor_dtype": "prediction", "weather": "traffic",
    "traffic_speed_offset_kmh": "traffic", "objective": "question", "miss_penalty_m2": "question",
    "steps": "solver", "solve": "solver", "dense_check": "solver", "extra_curve_points": "solver",
    "cost_weight": "question", "costs": "question", "box": "solver", "window_s": "traffic", "crossing_at_s": "traffic",
    "target_ci": "traffic",
}
_SPECS = {"traffic": TrafficSpec, "sensing": SensingSpec, "prediction": PredictionSpec, "question": QuestionSpec,
          "solver": SolverSpec}


def _spec(stage: str, keywords: Mapping[str, Any]) -> Any:
    """The spec of `stage` from the flat keywords (a fill of None: the profile's)."""
    fields = {name: keywords[name] for name, at in STAGE_OF.items() if at == stage}
    if stage == "prediction" and fields["fill"] is None:
        fields["fill"] = profile_fill(keywords["profile"])
    return _SPECS[stage](**fields)


@dataclasses.dataclass(frozen=True, init=False)
class Problem:
    """An optimisation problem: argmin over r in the box `sensing.params` of E(r).

    `Problem(**keywords)` takes every field of the five specs flat (each described on its spec:
    `TrafficSpec`, `SensingSpec`, `PredictionSpec`, `QuestionSpec`, `SolverSpec`) and the seed;
    `Problem.from_specs` takes the specs themselves. Either way each spec is checked once, where
    it is defined, and the Problem checks that they agree (the paper profile's clear weather,
    the one-parameter settings meeting one parameter).

    Attributes:
        traffic, sensing, prediction, question, solver: the specs.
        seed: fixes scene variants, measurement noise and Monte-Carlo draws, in [0, 2^32 - 1].
    """

    traffic: TrafficSpec
    sensing: SensingSpec
    prediction: PredictionSpec
    question: QuestionSpec
    solver: SolverSpec
    seed: int

    def __init__(
        self,
        sensor: str | Sensor | Sequence[str | Sensor] | Mapping[str, Any] = "radar",
        params: Mapping[str, tuple[float, float]] | None = None,
        scenarios: Sequence[str] = PAPER_SCENARIOS,
        scenes: str | None = None,
        variants: int = 8,
        seed: int = 0,
        predictor: str | Predictor = "",
        profile: str = "physical",
        sensor_config: str | Mapping[str, str] | None = None,
        fill: str | None = None,
        estimator: str | EstimatorConfig = "auto",
        prediction_stride_frames: int = 4,
        background_vehicles: int = 0,
        float64: bool = True,
        predictor_dtype: str = "auto",
        weather: Mapping[str, float] | None = None,
        traffic_speed_offset_kmh: float = 0.0,
        objective: str = "eq12",
        miss_penalty_m2: float = 100.0,
        steps: Sequence[float] | None = None,
        solve: SolveConfig = SolveConfig(),
        dense_check: float | None = None,
        extra_curve_points: int = 0,
        cost_weight: float = 0.0,
        costs: str | None = None,
        box: BoxConfig = BoxConfig(),
        window_s: float = DEFAULT_WINDOW_S,
        crossing_at_s: float | None = None,
        target_ci: float | None = None,
    ):
        keywords = dict(locals())  # the arguments, by name
        del keywords["self"]
        if params is None:
            keywords["params"] = {"hfov_deg": (30.0, 180.0)}
        # The sensor and its parameters first: of several bad keywords, theirs is the refusal a user meets.
        specs = {stage: _spec(stage, keywords) for stage in ("sensing", "question", "traffic", "prediction", "solver")}
        self._hold(specs, seed)

    def _hold(self, specs: Mapping[str, Any], seed: int) -> None:
        for stage, spec in specs.items():
            object.__setattr__(self, stage, spec)
        object.__setattr__(self, "seed", check_int("seed", seed, 0, MAX_SEED))
        if self.sensing.profile == "paper" and self.traffic.weather not in (None, CLEAR_WEATHER):
            raise InputError("the paper profile is the paper's clear-weather design: use the physical profile for weather")
        self.solver.check_bounds(self.sensing.params)

    @classmethod
    def from_specs(cls, *, traffic: TrafficSpec | None = None, sensing: SensingSpec | None = None,
                   prediction: PredictionSpec | None = None, question: QuestionSpec | None = None,
                   solver: SolverSpec | None = None, seed: int = 0) -> Problem:
        """A problem from its specs (each left out: its defaults)."""
        given = {"traffic": traffic, "sensing": sensing, "prediction": prediction, "question": question,
                 "solver": solver}
        problem = object.__new__(cls)
        problem._hold({stage: _SPECS[stage]() if spec is None else spec for stage, spec in given.items()}, seed)
        return problem

    def keywords(self) -> dict[str, Any]:
        """The flat keyword arguments that build this problem again (`Problem(**p.keywords()) == p`),
        each in its spec's normal form, in the constructor's order."""
        return {name: self.seed if stage is None else getattr(getattr(self, stage), name)
                for name, stage in STAGE_OF.items()}

    def replace(self, **changes: Any) -> Problem:
        """This problem with the flat keywords `changes` replaced (`dataclasses.replace` for the
        specs' fields): only the specs they belong to are built again, the sensor only when a
        sensing field changes."""
        unknown = sorted(set(changes) - set(STAGE_OF))
        if unknown:
            raise TypeError(f"Problem.replace() got an unexpected keyword argument {unknown[0]!r}")
        keywords = self.keywords() | changes
        touched = {STAGE_OF[name] for name in changes} - {None}
        specs = {stage: _spec(stage, keywords) if stage in touched else getattr(self, stage) for stage in _SPECS}
        problem = object.__new__(type(self))
        problem._hold(specs, keywords["seed"])
        return problem

    @property
    def params(self) -> dict[str, tuple[float, float]]:
        """The free parameters and their bounds, names resolved (`sensing.params`)."""
        return self.sensing.params

    @property
    def sensor_kind(self) -> str:
        """The sensor's short name ("radar", "camera", a custom sensor's; "radar+camera" for a
        suite: `sensing.kind`)."""
        return self.sensing.kind

    @classmethod
    def from_toml(cls, path: str | Path | None = None, **overrides: Any) -> Problem:
        """A problem from a TOML in the layout of `configs/optimise/default.toml` (None: that
        file). Keys the file leaves out keep the shipped defaults; `overrides` replace fields."""
        return cls(**problem_fields(load_settings(path)) | overrides)

    @classmethod
    def from_suite(cls, path: str | Path, **overrides: Any) -> Problem:
        """A suite design problem from a suite file (`configs/suites/*.toml`: its sensors, free
        parameters with bounds and cost weight; layout in `diffsense.study.load_suite`).
        `overrides` replace fields (scenarios, variants, ...); a refusal names the file."""
        fields = load_suite(path)
        return checked(path, lambda: cls(**fields | overrides))


def problem_config(problem: Problem) -> dict[str, Any]:
    """The problem as result.json's `config`: its flat keywords as plain values, the sensor and
    predictor by name."""
    fields = problem.keywords()
    fields["sensor"] = problem.sensing.member_names()
    if not isinstance(fields["predictor"], str):
        fields["predictor"] = type(fields["predictor"]).__name__
    fields["params"] = {k: list(v) for k, v in problem.params.items()}
    return cfgio.to_dict(fields)
