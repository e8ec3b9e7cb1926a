"""Scenario configs (configs/scenarios/*.toml) and the vehicle models they share.

A scenario places an ego, a target that changes lane into the ego's lane (in front of the ego or
in front of the ego's lead), the lead, the vehicle ahead of the target in its own lane and one in
an adjacent lane, plus optional background traffic. Every randomised quantity is a `Range`: the
nominal value makes variant 0, the randomised variants draw uniformly from [low, high].
Speeds are in km/h in the files (what a scenario author thinks in) and SI inside.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Literal

from diffsense.config import list_defaults, load_default
from diffsense.runtime import InputError
from diffsense.scene._named_config import load_named

KindName = Literal["car", "van", "truck"]
# Quintic lane-change durations outside this band are not what the paper's scenarios describe.
LANE_CHANGE_DURATION_BOUNDS_S = (3.0, 6.0)
_VEHICLE_MODELS = "scenarios/common/vehicles.toml"


@dataclasses.dataclass(frozen=True)
class Range:
    """A randomised quantity: `nominal` for variant 0, uniform in [low, high] for the others."""

    nominal: float
    low: float
    high: float

    def __post_init__(self):
        if not self.low <= self.nominal <= self.high:
            raise InputError(f"range needs low <= nominal <= high, got {self.low}, {self.nominal}, {self.high}")


@dataclasses.dataclass(frozen=True)
class EgoSpec:
    """The ego vehicle (vehicle 0).

    Attributes:
        lane: its lane (0 = rightmost); the target changes into it.
        s_m: arc length of the ego's centre at t = 0 [m].
        speed_kmh: its speed at t = 0 [km/h].
        kind: vehicle kind (the paper's ego is a passenger car).
    """

    lane: int
    s_m: Range
    speed_kmh: Range
    kind: KindName = "car"


@dataclasses.dataclass(frozen=True)
class VehicleSpec:
    """A scenario vehicle placed relative to another one.

    Attributes:
        position_m: where it starts; what it is measured from is the role's (see ScenarioConfig) [m].
        relative_speed_kmh: its speed at t = 0 minus the ego's [km/h].
        kind: kind in the nominal variant.
        random_kinds: kinds a randomised variant draws from (uniformly).
    """

    position_m: Range
    relative_speed_kmh: Range
    kind: KindName = "car"
    random_kinds: tuple[KindName, ...] = ("car",)

    def __post_init__(self):
        if not self.random_kinds:
            raise InputError("random_kinds must name at least one kind")


@dataclasses.dataclass(frozen=True)
class LaneChangeSpec:
    """The target's lane change (quintic lateral profile)."""

    start_s: Range
    duration_s: Range

    def __post_init__(self):
        lo, hi = LANE_CHANGE_DURATION_BOUNDS_S
        if not (lo <= self.duration_s.low and self.duration_s.high <= hi):
            raise InputError(f"lane_change.duration_s must lie in [{lo}, {hi}] s, got "
                             f"[{self.duration_s.low}, {self.duration_s.high}]")
        if self.start_s.low < 0.0:
            raise InputError(f"lane_change.start_s must be >= 0 s, got {self.start_s.low}")


@dataclasses.dataclass(frozen=True)
class BackgroundSpec:
    """Background traffic: `count` IDM vehicles behind the ego, vehicle i in lane i % lanes and
    row i // lanes, `gap_m` behind the ego and `spacing_m` apart; with `mobil` they change lanes
    by MOBIL (quintic, `lane_change_duration_s` long). Placed far back, they never reach the
    target's social grid: they show that the cost downstream does not grow with them."""

    count: int = 0
    gap_m: float = 150.0
    spacing_m: float = 40.0
    relative_speed_kmh: Range = Range(0.0, -10.0, 10.0)
    kind: KindName = "car"
    mobil: bool = True
    lane_change_duration_s: float = 4.0

    def __post_init__(self):
        lo, hi = LANE_CHANGE_DURATION_BOUNDS_S
        if not lo <= self.lane_change_duration_s <= hi:
            raise InputError(f"background.lane_change_duration_s must lie in [{lo}, {hi}] s, got {self.lane_change_duration_s}")
        if not 0 <= self.count <= 10_000:
            raise InputError(f"background.count must be in [0, 10000], got {self.count}")
        if not (self.gap_m > 0.0 and self.spacing_m > 0.0):
            raise InputError("background.gap_m and background.spacing_m must be > 0")


@dataclasses.dataclass(frozen=True)
class WeatherSpec:
    """The scenario's weather (its ODD): `rain_mm_h` [mm/h], 0 for none; `fog_visibility_m` [m],
    0 for no fog (TOML has no "none"). The sensors model its effect (diffsense.sensors.Weather)."""

    rain_mm_h: float = 0.0
    fog_visibility_m: float = 0.0

    def __post_init__(self):
        if not 0.0 <= self.rain_mm_h <= 500.0:
            raise InputError(f"weather.rain_mm_h must be in [0, 500], got {self.rain_mm_h}")
        if not (self.fog_visibility_m == 0.0 or self.fog_visibility_m >= 1.0):
            raise InputError(f"weather.fog_visibility_m must be 0 (no fog) or >= 1 m, got {self.fog_visibility_m}")


@dataclasses.dataclass(frozen=True)
class ScenarioConfig:
    """One of the paper's lane-change scenarios.

    Positions (`position_m`, bumper to bumper unless said otherwise, positive ahead):
        lead: gap from the ego's front to the lead's rear (same lane as the ego).
        target: gap from the front of `target_ahead_of` (the ego or the lead) to the target's rear.
        target_lead: gap from the target's front to its rear (the target's starting lane).
        adjacent: centre-to-centre offset from the target (in `adjacent_lane`).
    """

    name: str
    road: str
    direction: Literal["left", "right"]
    target_ahead_of: Literal["ego", "lead"]
    target_lane: int
    adjacent_lane: int
    ego: EgoSpec
    target: VehicleSpec
    lead: VehicleSpec
    target_lead: VehicleSpec
    adjacent: VehicleSpec
    lane_change: LaneChangeSpec
    description: str = ""
    duration_s: float = 20.0
    background: BackgroundSpec = BackgroundSpec()
    weather: WeatherSpec = WeatherSpec()

    def __post_init__(self):
        step = -1 if self.direction == "right" else 1  # lane 0 is the rightmost
        if self.target_lane + step != self.ego.lane:
            raise InputError(f"a lane change to the {self.direction} into the ego's lane {self.ego.lane} "
                             f"must start in lane {self.ego.lane - step}, got target_lane {self.target_lane}")
        if self.adjacent_lane in (self.ego.lane, self.target_lane):
            raise InputError(f"adjacent_lane must differ from the ego's and the target's, got {self.adjacent_lane}")
        slowest_kmh = slowest_start_kmh(self)
        if slowest_kmh <= 0.0:
            raise InputError(f"every vehicle must start moving forward: ego.speed_kmh.low plus the lowest "
                             f"relative_speed_kmh is {slowest_kmh} km/h")
        if not 1.0 <= self.duration_s <= 120.0:
            raise InputError(f"duration_s must be in [1, 120] s, got {self.duration_s}")


def slowest_start_kmh(cfg: ScenarioConfig) -> float:
    """The lowest start speed any vehicle of any variant of `cfg` can draw [km/h]."""
    specs = (cfg.target, cfg.lead, cfg.target_lead, cfg.adjacent)
    return cfg.ego.speed_kmh.low + min(0.0, *(sp.relative_speed_kmh.low for sp in specs),
                                       cfg.background.relative_speed_kmh.low)


def check_speed_offset(cfg: ScenarioConfig, speed_offset_kmh: float) -> None:
    """InputError unless every vehicle of `cfg` still starts moving with its speeds moved by
    `speed_offset_kmh` (see `diffsense.scene.simulate_scenario`)."""
    slowest = slowest_start_kmh(cfg)
    if not slowest + speed_offset_kmh > 0.0:
        raise InputError(f"{cfg.name}: a traffic speed offset of {speed_offset_kmh:g} km/h stops its slowest "
                         f"vehicle (start speed {slowest:g} km/h): every vehicle must start moving")


@dataclasses.dataclass(frozen=True)
class KindModel:
    """Body size of a vehicle kind [m]."""

    length_m: float
    width_m: float


@dataclasses.dataclass(frozen=True)
class DriverModel:
    """IDM parameters shared by every scenario vehicle, and the simulation's limits.

    Desired speeds and followers' time headways are not here: each vehicle's are derived from its
    start so that the scene starts in steady state (see _simulate._idm).
    """

    time_headway_s: float
    min_gap_m: float
    max_accel_mps2: float
    comfort_decel_mps2: float
    accel_exponent: float
    max_brake_mps2: float
    follower_speed_ratio: float
    min_time_headway_s: float
    max_time_headway_s: float
    lateral_margin_m: float

    def __post_init__(self):
        if not self.follower_speed_ratio > 1.0:
            raise InputError(f"driver.follower_speed_ratio must be > 1, got {self.follower_speed_ratio}")
        if not 0.0 < self.min_time_headway_s <= self.max_time_headway_s:
            raise InputError("driver time headways need 0 < min_time_headway_s <= max_time_headway_s")


@dataclasses.dataclass(frozen=True)
class LaneChangeModel:
    """MOBIL parameters of the background vehicles (see diffsense.scene.MOBILParams)."""

    politeness: float
    threshold_mps2: float
    safe_decel_mps2: float
    keep_right_bias_mps2: float
    decision_period_s: float

    def __post_init__(self):
        if not 0.1 <= self.decision_period_s <= 10.0:
            raise InputError(f"mobil.decision_period_s must be in [0.1, 10] s, got {self.decision_period_s}")


@dataclasses.dataclass(frozen=True)
class VehicleModels:
    """configs/scenarios/common/vehicles.toml: kinds' sizes, the driver model, MOBIL."""

    car: KindModel
    van: KindModel
    truck: KindModel
    driver: DriverModel
    mobil: LaneChangeModel

    def size(self, kind: str) -> KindModel:
        return getattr(self, kind)


def list_scenarios() -> list[str]:
    """Names of the shipped scenarios (configs/scenarios/*.toml)."""
    return list_defaults("scenarios")


def load_scenario(name_or_path: str | Path) -> ScenarioConfig:
    """A shipped scenario by name (`"sc01"`) or a scenario TOML file by path."""
    return load_named(ScenarioConfig, "scenarios", name_or_path, "scenario")


def load_vehicle_models() -> VehicleModels:
    """The shipped vehicle kinds and driver model."""
    return load_default(VehicleModels, _VEHICLE_MODELS)
