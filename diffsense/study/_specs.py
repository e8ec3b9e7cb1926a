"""What a problem is made of, one small frozen spec per stage, each checked where it is defined:

    TrafficSpec     what the scenes are: scenarios (or a recording), variants, weather, speed
    SensingSpec     which sensor(s) with which constants, and the free parameters with bounds
    PredictionSpec  which predictor, in which precision, fed by which missing-detection fill
    QuestionSpec    what E answers: the question, its estimator, the price of a design
    SolverSpec      how the answer is searched: the sweep's steps, the solve's settings

A spec refuses what it cannot hold with one `InputError` line naming the culprit, and holds its
values in one form (a scenario list as a tuple, an estimator name as its `EstimatorConfig`, ...).
`SensingSpec` builds its sensor once, resolves the parameter names against it once, and keeps
both: everything downstream reads them from the spec.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from diffsense.metrics import PAPER_SCENARIOS, QUESTIONS, EstimatorConfig
from diffsense.predictors import COMPUTE_DTYPES, Predictor
from diffsense.runtime import InputError, finite_number
from diffsense.scene import DEFAULT_WINDOW_S, check_window
from diffsense.sensors import ParamSpec, Sensor, Suite, make_sensor, resolve_params
from diffsense.solve import BoxConfig, SolveConfig
from diffsense.study._members import Member, build_suite, is_named, named_members
from diffsense.tracks import FILL_POLICIES

WEATHER_DOMAINS = {"rain_mm_h": (0.0, 500.0), "fog_visibility_m": (1.0, math.inf)}
CLEAR_WEATHER = {"rain_mm_h": 0.0, "fog_visibility_m": math.inf}


def _hold(spec: Any, **values: Any) -> None:
    """Sets fields of a frozen spec from its own `__post_init__` (their one normal form)."""
    for name, value in values.items():
        object.__setattr__(spec, name, value)


def check_int(name: str, value: Any, lo: int, hi: int) -> int:
    """`value` if it is an integer in [lo, hi] (a bool is not); InputError naming `name` otherwise."""
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise InputError(f"{name} must be an integer in [{lo}, {hi}], got {value!r}")
    return value


def _scenario_names(scenarios: str | Sequence[str]) -> tuple[str, ...]:
    names = scenarios.split(",") if isinstance(scenarios, str) else list(scenarios)
    names = [str(n).strip() for n in names]
    if not names or not all(names):
        raise InputError("at least one scenario is needed (an empty name was given)")
    if len(set(names)) != len(names):
        raise InputError(f"scenario named twice: {sorted(n for n in set(names) if names.count(n) > 1)[0]}")
    return tuple(names)


def _weather(weather: Mapping[str, Any]) -> dict[str, float]:
    """The weather as {"rain_mm_h", "fog_visibility_m"}, each checked against its domain."""
    out = dict(CLEAR_WEATHER)
    for name, value in weather.items():
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


def _recorded(scenes: Any) -> None:
    kind, sep, path = str(scenes).partition(":")
    if kind not in ("highd", "ngsim") or not sep or not path:
        raise InputError(f"recorded scenes are named 'highd:PATH' or 'ngsim:PATH', got {scenes!r}")
    if not Path(path).is_file():
        raise InputError(f"recorded scenes: {path} is not a file")


@dataclasses.dataclass(frozen=True)
class TrafficSpec:
    """What the scenes are: the traffic the sensor watches, simulated or recorded.

    Attributes:
        scenarios: scenario names or TOML paths (a comma-separated string is split) [-].
        scenes: recorded traffic instead of scenarios: "highd:PATH" (a highD NN_tracks.csv, its
            two sibling files beside it) or "ngsim:PATH" (an NGSIM trajectory CSV); one scene per
            usable lane change (`diffsense.scene.load_recorded`). None: the scenarios.
        variants: scene variants per scenario (variant 0 nominal, the rest randomised) [-].
        prediction_stride_frames: one prediction instant every this many scene frames [-].
        background_vehicles: if > 0, replaces every scenario's count of far background vehicles [-].
        weather: {"rain_mm_h": R [mm/h], "fog_visibility_m": V [m]} for every scenario, either left
            out meaning none (held with both keys); None: each scenario's own (its TOML's
            `[weather]`, clear for the shipped ones).
        traffic_speed_offset_kmh: added to every scenario's ego start speed, and so to every
            vehicle's (theirs are relative to it): the ODD's traffic speed [km/h]; 0 keeps the
            scenarios' own. Not for recorded scenes, which move at the speeds they were recorded at.
        window_s: recorded scenes only: the length of the window cut around each lane change, at
            least the predictor's 3 s history and 5 s future [s] (`diffsense.scene.recorded_scenes`).
        crossing_at_s: recorded scenes only: where in the window the lane change crosses the
            marking [s from its start]; None: each window placed to fit the recording.
        target_ci: the one-parameter job doubles the variants (from `variants`, up to a cap) until
            the decision's interval has a half-width under this [m] or excludes 0
            (`diffsense.optimise`); None: `variants` as given. Not for recorded scenes.
    """

    scenarios: Sequence[str] = PAPER_SCENARIOS
    scenes: str | None = None
    variants: int = 8
    prediction_stride_frames: int = 4
    background_vehicles: int = 0
    weather: Mapping[str, float] | None = None
    traffic_speed_offset_kmh: float = 0.0
    window_s: float = DEFAULT_WINDOW_S
    crossing_at_s: float | None = None
    target_ci: float | None = None

    def __post_init__(self):
        _hold(self, scenarios=_scenario_names(self.scenarios))
        check_int("variants", self.variants, 1, 100_000)
        check_int("prediction_stride_frames", self.prediction_stride_frames, 1, 1000)
        check_int("background_vehicles", self.background_vehicles, 0, 10_000)
        _hold(self, weather=None if self.weather is None else _weather(self.weather))
        if self.scenes is not None:
            _recorded(self.scenes)
        _hold(self, traffic_speed_offset_kmh=finite_number(self.traffic_speed_offset_kmh, "traffic_speed_offset_kmh"))
        if self.scenes is not None and self.traffic_speed_offset_kmh != 0.0:
            raise InputError("recorded scenes have the speeds they were recorded at: traffic_speed_offset_kmh "
                             "applies to simulated scenarios only")
        _hold(self, window_s=finite_number(self.window_s, "window_s"))
        if self.crossing_at_s is not None:
            _hold(self, crossing_at_s=finite_number(self.crossing_at_s, "crossing_at_s"))
        if self.scenes is None and (self.window_s != DEFAULT_WINDOW_S or self.crossing_at_s is not None):
            raise InputError("window_s and crossing_at_s cut windows from recorded scenes (scenes=...): the "
                             "scenarios have their own duration")
        check_window(self.window_s, self.crossing_at_s, 1.0)
        if self.target_ci is not None:
            _hold(self, target_ci=finite_number(self.target_ci, "target_ci"))
            if self.target_ci <= 0.0:
                raise InputError(f"target_ci must be a positive half-width [m], got {self.target_ci!r}")
            if self.scenes is not None:
                raise InputError("target_ci adds scene variants: recorded scenes (scenes=...) have none to add")


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


@dataclasses.dataclass(frozen=True)
class SensingSpec:
    """Which sensor(s), with which constants, and the free parameters r with their bounds.

    Attributes:
        sensor: a registered sensor name ("radar", "camera"), a `diffsense.sensors.Sensor`, or a
            sequence of them (held as a tuple): a suite, fused into one track per vehicle
            (`diffsense.sensors.Suite`), its members named by their kinds. Or a suite of named
            members, {name: kind or {"kind", "sensor_config", "yaw_deg", "mount_x_m",
            "mount_y_m", "envelope"}} (two of one kind allowed), held as a tuple of `Member`s
            (which it also takes): `diffsense.study.named_members`.
        params: {name: (lo, hi)}: the free parameters and their bounds, in the units their names
            carry ("hfov_deg": degrees). Short names ("hfov") are resolved to the sensor's full
            ones, once, here; a suite's are qualified by the member ("radar.hfov_deg").
        profile: the sensors' shipped constants: "physical" or "paper" (the paper's
            experimental design: see configs/sensors/paper/).
        sensor_config: a TOML of sensor constants (any subset) replacing the profile's; for a
            suite, {member name: TOML} (e.g. {"radar": "radar_swerling1.toml"}), members not
            named keeping their profile's. Named members carry their own (None here).
        built: the sensor itself, built once from the four above (not an argument); `kind` and
            `specs` read it.
    """

    sensor: str | Sensor | Sequence[str | Sensor] | Mapping[str, Any] | Sequence[Member] = "radar"
    params: Mapping[str, tuple[float, float]] = dataclasses.field(default_factory=lambda: {"hfov_deg": (30.0, 180.0)})
    profile: str = "physical"
    sensor_config: str | Mapping[str, str] | None = None
    built: Sensor = dataclasses.field(init=False, repr=False, compare=False)

    def __post_init__(self):
        if is_named(self.sensor):
            _hold(self, sensor=named_members(self.sensor))
            if self.sensor_config is not None:
                raise InputError("a suite of named members gives each member its own sensor_config")
            built = build_suite(self.sensor, self.profile)
        else:
            if isinstance(self.sensor, list):
                _hold(self, sensor=tuple(self.sensor))
            built = (_suite_with_configs(self.sensor, self.sensor_config, self.profile)
                     if isinstance(self.sensor_config, Mapping) else make_sensor(self.sensor, self.sensor_config, self.profile))
        _hold(self, built=built, params=resolve_params(built, self.params))

    @property
    def kind(self) -> str:
        """The sensor's short name: "radar", "camera", a custom sensor's; "radar+camera" for a suite."""
        return "+".join(self.built.names) if hasattr(self.built, "members") else self.built.kind

    @property
    def specs(self) -> dict[str, ParamSpec]:
        """{name: ParamSpec} of every free parameter: its unit, domain and default."""
        return {name: self.built.spec(name) for name in self.params}

    def member_names(self) -> str | list[str] | dict[str, dict[str, Any]]:
        """The sensor as result.json's config names it: its kind, a suite's member names, or
        named members in their mapping form ({name: {"kind", ...}})."""
        if is_named(self.sensor):
            return {m.name: m.as_plain() for m in self.sensor}
        if isinstance(self.sensor, tuple):
            return [s if isinstance(s, str) else s.kind for s in self.sensor]
        return self.kind


def profile_fill(profile: str) -> str:
    """A profile's missing-detection fill: the paper's "zero" for "paper", "hold" otherwise."""
    return "zero" if profile == "paper" else "hold"


@dataclasses.dataclass(frozen=True)
class PredictionSpec:
    """Which predictor forecasts the target, in which precision, fed by which fill.

    Attributes:
        predictor: "" for the shipped CS-LSTM weights, a weight/checkpoint path, or any object
            implementing `diffsense.predictors.Predictor`.
        predictor_dtype: the float type the predictor computes in: "float32", "float64",
            "bfloat16" (the CS-LSTM in float32 with its LSTM products on bfloat16 operands:
            faster, predictions centimetres off), or "auto": float32 for the CS-LSTM, whose
            weights are float32 and which costs half as much in float32 on a CPU; E's own type
            for any other predictor. Its inputs and
            output stay in E's type, so E and dE/dr keep float64 around it
            (`diffsense.predictors.with_compute_dtype`).
        float64: compute E(r) in float64 (enables JAX's x64 mode when needed).
        fill: missing-detection policy of the tracks the predictor reads: "zero", "hold" or
            "interp" (`Problem` fills in its profile's when given None: `profile_fill`).
    """

    predictor: str | Predictor = ""
    predictor_dtype: str = "auto"
    float64: bool = True
    fill: str = "hold"

    def __post_init__(self):
        if self.predictor_dtype not in ("auto", *COMPUTE_DTYPES):
            raise InputError(f"predictor_dtype must be auto, {', '.join(COMPUTE_DTYPES)}, got {self.predictor_dtype!r}")
        if self.predictor_dtype == "float64" and not self.float64:
            raise InputError("predictor_dtype float64 needs float64 = true (a float32 E cannot carry its digits)")
        if self.fill not in FILL_POLICIES:
            raise InputError(f"unknown fill {self.fill!r} (known: {', '.join(FILL_POLICIES)})")


@dataclasses.dataclass(frozen=True)
class QuestionSpec:
    """What E answers, how detection uncertainty enters it, and what a design costs.

    Attributes:
        objective: the question: "eq12" (the paper's, every instant) or "tracked" (the error
            where the target has a track, plus `miss_penalty_m2` per missed share).
        miss_penalty_m2: the price of an instant without a track under "tracked" [m^2].
        estimator: how detection uncertainty enters ("auto", "mean-field", "mc",
            "relaxed-reference", "straight-through", "hard"; held as its `EstimatorConfig`,
            which carries the knobs: see `diffsense.metrics.EstimatorConfig`).
        cost_weight: lambda in the objective E + lambda * cost [m per currency unit] (0: E alone).
        costs: a cost-model TOML (None: configs/costs.toml).
    """

    objective: str = "eq12"
    miss_penalty_m2: float = 100.0
    estimator: str | EstimatorConfig = "auto"
    cost_weight: float = 0.0
    costs: str | None = None

    def __post_init__(self):
        if isinstance(self.estimator, str):
            _hold(self, estimator=EstimatorConfig(kind=self.estimator))
        if self.objective not in QUESTIONS:
            raise InputError(f"unknown objective {self.objective!r} (known: {', '.join(QUESTIONS)})")
        _hold(self, miss_penalty_m2=finite_number(self.miss_penalty_m2, "miss_penalty_m2"),
              cost_weight=finite_number(self.cost_weight, "cost_weight"))
        if self.miss_penalty_m2 < 0:
            raise InputError(f"miss_penalty_m2 must be >= 0, got {self.miss_penalty_m2:g}")
        if self.cost_weight < 0:
            raise InputError(f"cost_weight must be >= 0, got {self.cost_weight:g}")


@dataclasses.dataclass(frozen=True)
class SolverSpec:
    """How the answer is searched, and what is evaluated beside it for the figures and checks.

    Attributes:
        steps: the stepped sweep's points, in the parameter's unit (one-parameter problems;
            None: the default steps).
        solve: settings of the one-parameter continuous solve (`diffsense.solve.SolveConfig`).
        dense_check: if set, `optimise` also evaluates the reference E every this many parameter
            units (one-parameter problems) [parameter unit].
        extra_curve_points: evenly spaced extra E(r) points evaluated for the objective figure [-].
        box: settings of the many-parameter solve (`diffsense.solve.BoxConfig`).
    """

    steps: Sequence[float] | None = None
    solve: SolveConfig = SolveConfig()
    dense_check: float | None = None
    extra_curve_points: int = 0
    box: BoxConfig = BoxConfig()

    def __post_init__(self):
        check_int("extra_curve_points", self.extra_curve_points, 0, 1000)
        if self.steps is not None:
            _hold(self, steps=tuple(finite_number(v, "steps") for v in self.steps))
        if self.dense_check is not None and not (math.isfinite(self.dense_check) and self.dense_check > 0):
            raise InputError(f"dense_check must be a positive step, got {self.dense_check}")

    def check_bounds(self, params: Mapping[str, tuple[float, float]]) -> None:
        """InputError unless the one-parameter settings meet one parameter, and the dense check
        makes at most 100,000 points on its interval."""
        if self.steps is not None and len(params) != 1:
            raise InputError("steps apply to one-parameter problems only")
        if self.dense_check is not None and len(params) > 1:
            raise InputError("dense_check applies to one-parameter problems only")
        if self.dense_check is not None:
            for lo, hi in params.values():
                if (hi - lo) / self.dense_check > 100_000:
                    raise InputError(f"dense_check {self.dense_check:g} makes over 100,000 points on [{lo:g}, {hi:g}]")
