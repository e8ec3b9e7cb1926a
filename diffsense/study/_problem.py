"""`Problem`: what to optimise (sensor, named parameters with bounds) and over what (scenes).

A Problem is plain, frozen data: building it simulates nothing. `diffsense.objective(problem)`
turns it into E(r); `diffsense.optimise(problem)` runs the main job on it. `Problem.from_toml`
reads the layout of `configs/optimise/default.toml`; a file may be partial, and the keys it
leaves out keep the shipped defaults.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from diffsense import config as cfgio
from diffsense.metrics import PAPER_SCENARIOS, QUESTIONS, EstimatorConfig
from diffsense.predictors import COMPUTE_DTYPES, Predictor
from diffsense.runtime import InputError, finite_number
from diffsense.sensors import ParamSpec, Sensor, Suite, make_sensor, resolve_params
from diffsense.solve import BoxConfig, SolveConfig
from diffsense.study._settings import load_settings, problem_fields
from diffsense.study._suite_file import checked, load_suite
from diffsense.tracks import FILL_POLICIES

_MAX_SEED = 2**32 - 1


@dataclasses.dataclass(frozen=True)
class Problem:
    """An optimisation problem: argmin over r in the box `params` of E(r).

    Attributes:
        sensor: a registered sensor name ("radar", "camera"), a `diffsense.sensors.Sensor`, or a
            list of them: a suite, fused into one track per vehicle (`diffsense.sensors.Suite`).
        params: {name: (lo, hi)}: the free parameters and their bounds, in the units their names
            carry ("hfov_deg": degrees). Short names ("hfov") are resolved to the sensor's; a
            suite's are qualified by the member ("radar.hfov_deg", "camera.width").
        scenarios: scenario names or TOML paths.
        scenes: recorded traffic instead of scenarios: "highd:PATH" (a highD NN_tracks.csv, its
            two sibling files beside it) or "ngsim:PATH" (an NGSIM trajectory CSV); one scene per
            usable lane change (`diffsense.scene.load_recorded`).
        variants: scene variants per scenario (variant 0 nominal, the rest randomised) [-].
        seed: fixes scene variants, measurement noise and Monte-Carlo draws.
        predictor: "" for the shipped CS-LSTM weights, a weight/checkpoint path, or any object
            implementing `diffsense.predictors.Predictor`.
        profile: the sensors' shipped constants: "physical" (the default) or "paper" (the
            paper's experimental design: see configs/sensors/paper/).
        sensor_config: a TOML of sensor constants (any subset) replacing the profile's; for a
            suite, {member name: TOML} (e.g. {"radar": "radar_swerling1.toml"}), members not
            named keeping their profile's.
        fill: missing-detection policy: "zero", "hold" or "interp" (None: the profile's, "hold"
            for physical, the paper's "zero" for paper).
        estimator: how detection uncertainty enters ("auto", "mean-field", "mc",
            "relaxed-reference", "straight-through", "hard", or an `EstimatorConfig` with its
            knobs; see `diffsense.metrics.EstimatorConfig`).
        prediction_stride_frames: one prediction instant every this many scene frames [-].
        background_vehicles: if > 0, replaces every scenario's count of far background vehicles.
        float64: compute E(r) in float64 (enables JAX's x64 mode when needed).
        predictor_dtype: the float type the predictor computes in: "float32", "float64", or
            "auto" (the default): float32 for the CS-LSTM, whose weights are float32 and which
            costs half as much in float32 on a CPU; E's own type for any other predictor. Its
            inputs and output stay in E's type, so E and dE/dr keep float64 around it
            (`diffsense.predictors.with_compute_dtype`).
        weather: the scenes' weather, {"rain_mm_h": R, "fog_visibility_m": V} (either may be left
            out: no rain, no fog), for every scenario; None: each scenario's own (its TOML's
            `[weather]`, clear for the shipped ones).
        traffic_speed_offset_kmh: added to every scenario's ego start speed, and so to every
            vehicle's (theirs are relative to it): the ODD's traffic speed [km/h]; 0 keeps the
            scenarios' own. Not for recorded scenes.
        objective: the question E answers: "eq12" (the paper's, every instant) or "tracked"
            (the error where the target has a track, plus `miss_penalty_m2` per missed share).
        miss_penalty_m2: the price of an instant without a track under "tracked" [m^2].
        steps: the stepped sweep's points (one-parameter problems; None: the default steps).
        solve: settings of the continuous solve.
        dense_check: if set, `optimise` also evaluates E_hard every this many parameter units.
        cost_weight: lambda in the objective E + lambda * cost [m per currency unit] (0: E alone).
        costs: a cost-model TOML (None: configs/costs.toml).
        box: settings of the many-parameter solve (`diffsense.solve.BoxConfig`).
        extra_curve_points: evenly spaced extra E(r) points evaluated for the objective figure.
    """

    sensor: str | Sensor | Sequence[str | Sensor] = "radar"
    params: Mapping[str, tuple[float, float]] = dataclasses.field(default_factory=lambda: {"hfov_deg": (30.0, 180.0)})
    scenarios: Sequence[str] = PAPER_SCENARIOS
    scenes: str | None = None
    variants: int = 8
    seed: int = 0
    predictor: str | Predictor = ""
    profile: str = "physical"
    sensor_config: str | Mapping[str, str] | None = None
    fill: str | None = None
    estimator: str | EstimatorConfig = "auto"
    prediction_stride_frames: int = 4
    background_vehicles: int = 0
    float64: bool = True
    predictor_dtype: str = "auto"
    weather: Mapping[str, float] | None = None
    traffic_speed_offset_kmh: float = 0.0
    objective: str = "eq12"
    miss_penalty_m2: float = 100.0
    steps: Sequence[float] | None = None
    solve: SolveConfig = SolveConfig()
    dense_check: float | None = None
    extra_curve_points: int = 0
    cost_weight: float = 0.0
    costs: str | None = None
    box: BoxConfig = BoxConfig()

    def __post_init__(self):
        set_ = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731 (frozen)
        if isinstance(self.sensor, list):
            set_("sensor", tuple(self.sensor))
        sensor = self.make_sensor()
        set_("cost_weight", finite_number(self.cost_weight, "cost_weight"))
        if self.cost_weight < 0:
            raise InputError(f"cost_weight must be >= 0, got {self.cost_weight:g}")
        if self.fill is None:
            set_("fill", "zero" if self.profile == "paper" else "hold")
        set_("params", resolve_params(sensor, self.params))
        names = self.scenarios.split(",") if isinstance(self.scenarios, str) else list(self.scenarios)
        names = [str(n).strip() for n in names]
        if not names or not all(names):
            raise InputError("at least one scenario is needed (an empty name was given)")
        if len(set(names)) != len(names):
            raise InputError(f"scenario named twice: {sorted(n for n in set(names) if names.count(n) > 1)[0]}")
        set_("scenarios", tuple(names))
        if isinstance(self.estimator, str):
            set_("estimator", EstimatorConfig(kind=self.estimator))
        _check_int("variants", self.variants, 1, 100_000)
        _check_int("seed", self.seed, 0, _MAX_SEED)
        _check_int("prediction_stride_frames", self.prediction_stride_frames, 1, 1000)
        _check_int("background_vehicles", self.background_vehicles, 0, 10_000)
        _check_int("extra_curve_points", self.extra_curve_points, 0, 1000)
        set_("weather", None if self.weather is None else _weather(self.weather))
        if self.predictor_dtype not in ("auto", *COMPUTE_DTYPES):
            raise InputError(f"predictor_dtype must be auto, {' or '.join(COMPUTE_DTYPES)}, got {self.predictor_dtype!r}")
        if self.predictor_dtype == "float64" and not self.float64:
            raise InputError("predictor_dtype float64 needs float64 = true (a float32 E cannot carry its digits)")
        if self.profile == "paper" and self.weather is not None and self.weather != _weather(None):
            raise InputError("the paper profile is the paper's clear-weather design: use the physical profile for weather")
        if self.scenes is not None:
            kind, sep, path = str(self.scenes).partition(":")
            if kind not in ("highd", "ngsim") or not sep or not path:
                raise InputError(f"recorded scenes are named 'highd:PATH' or 'ngsim:PATH', got {self.scenes!r}")
            if not Path(path).is_file():
                raise InputError(f"recorded scenes: {path} is not a file")
        set_("traffic_speed_offset_kmh", finite_number(self.traffic_speed_offset_kmh, "traffic_speed_offset_kmh"))
        if self.scenes is not None and self.traffic_speed_offset_kmh != 0.0:
            raise InputError("recorded scenes have the speeds they were recorded at: traffic_speed_offset_kmh "
                             "applies to simulated scenarios only")
        if self.objective not in QUESTIONS:
            raise InputError(f"unknown objective {self.objective!r} (known: {', '.join(QUESTIONS)})")
        set_("miss_penalty_m2", finite_number(self.miss_penalty_m2, "miss_penalty_m2"))
        if self.miss_penalty_m2 < 0:
            raise InputError(f"miss_penalty_m2 must be >= 0, got {self.miss_penalty_m2:g}")
        if self.fill not in FILL_POLICIES:
            raise InputError(f"unknown fill {self.fill!r} (known: {', '.join(FILL_POLICIES)})")
        if self.steps is not None:
            if len(self.params) != 1:
                raise InputError("steps apply to one-parameter problems only")
            set_("steps", tuple(finite_number(v, "steps") for v in self.steps))
        if self.dense_check is not None and len(self.params) > 1:
            raise InputError("dense_check applies to one-parameter problems only")
        if self.dense_check is not None and not (math.isfinite(self.dense_check) and self.dense_check > 0):
            raise InputError(f"dense_check must be a positive step, got {self.dense_check}")
        if self.dense_check is not None:
            for lo, hi in self.params.values():
                if (hi - lo) / self.dense_check > 100_000:
                    raise InputError(f"dense_check {self.dense_check:g} makes over 100,000 points on [{lo:g}, {hi:g}]")

    def make_sensor(self) -> Sensor:
        """The sensor with the problem's profile and sensor config."""
        if isinstance(self.sensor_config, Mapping):
            return _suite_with_configs(self.sensor, self.sensor_config, self.profile)
        return make_sensor(self.sensor, self.sensor_config, self.profile)

    @property
    def sensor_kind(self) -> str:
        """The sensor's short name ("radar", "camera", a custom sensor's; "radar+camera" for a suite)."""
        sensor = self.make_sensor()
        return "+".join(sensor.names) if hasattr(sensor, "members") else sensor.kind

    def specs(self) -> dict[str, ParamSpec]:
        """The spec (unit, domain, default) of every free parameter."""
        sensor = self.make_sensor()
        return {name: sensor.spec(name) for name in self.params}

    @classmethod
    def from_toml(cls, path: str | Path | None = None, **overrides: Any) -> Problem:
        """A problem from a TOML in the layout of `configs/optimise/default.toml` (None: that
        file). Keys the file leaves out keep the shipped defaults; `overrides` replace fields."""
        return cls(**problem_fields(load_settings(path)) | overrides)

    @classmethod
    def from_suite(cls, path: str | Path, **overrides: Any) -> Problem:
        """A suite design problem from a suite file (`configs/suites/*.toml`: its sensors, free
        parameters with bounds and cost weight; layout in `diffsense.study._suite_file`). `overrides`
        replace fields (scenarios, variants, ...); a refusal names the file."""
        fields = load_suite(path)
        return checked(path, lambda: cls(**fields | overrides))


WEATHER_DOMAINS = {"rain_mm_h": (0.0, 500.0), "fog_visibility_m": (1.0, math.inf)}


def _weather(weather: Mapping[str, Any] | None) -> dict[str, float]:
    """The weather as {"rain_mm_h", "fog_visibility_m"}, each checked against its domain."""
    out = {"rain_mm_h": 0.0, "fog_visibility_m": math.inf}
    for name, value in (weather or {}).items():
        if name not in WEATHER_DOMAINS:
            raise InputError(f"unknown weather {name!r} (known: {', '.join(WEATHER_DOMAINS)})")
        lo, hi = WEATHER_DOMAINS[name]
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise InputError(f"weather {name} must be a number, got {value!r}") from None
        if math.isnan(v) or not lo <= v <= hi or (math.isinf(v) and name != "fog_visibility_m"):
            raise InputError(f"weather {name} = {value!r} is outside [{lo:g}, {hi:g}]")
        out[name] = v
    return out


def _suite_with_configs(sensor: Any, configs: Mapping[str, str], profile: str) -> Sensor:
    """A suite whose members named in `configs` take the constants of their TOML."""
    if not isinstance(sensor, tuple) or len(sensor) < 2:
        raise InputError("a sensor_config by member name is for a suite (two or more sensors); give one sensor a path")
    names = [s if isinstance(s, str) else s.kind for s in sensor]
    for name, path in configs.items():
        if name not in names:
            raise InputError(f"sensor_config names {name!r}, not a member of the suite ({', '.join(names)})")
        if not isinstance(sensor[names.index(name)], str):
            raise InputError(f"sensor_config for {name!r}: that member is a Sensor object, which carries its own constants")
        if not isinstance(path, (str, Path)):
            raise InputError(f"sensor_config for {name!r} must be a TOML path, got {path!r}")
    # A Sensor object member goes through make_sensor too: under another profile than "physical"
    # it is refused, as it is without a sensor_config (it carries its own constants).
    return Suite([make_sensor(s, configs.get(s) if isinstance(s, str) else None, profile) for s in sensor])


def _check_int(name: str, value: Any, lo: int, hi: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise InputError(f"{name} must be an integer in [{lo}, {hi}], got {value!r}")


def problem_config(problem: Problem) -> dict[str, Any]:
    """The problem as result.json's `config`: plain values, the sensor and predictor by name."""
    fields = {f.name: getattr(problem, f.name) for f in dataclasses.fields(problem)}
    fields["sensor"] = problem.sensor_kind
    if not isinstance(problem.predictor, str):
        fields["predictor"] = type(problem.predictor).__name__
    fields["params"] = {k: list(v) for k, v in problem.params.items()}
    if isinstance(problem.sensor, tuple):
        fields["sensor"] = [s if isinstance(s, str) else s.kind for s in problem.sensor]
    return cfgio.to_dict(fields)
