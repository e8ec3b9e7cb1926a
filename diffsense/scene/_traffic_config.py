"""The training-traffic generator's config: ring highway, traffic ranges, vehicle kinds, sampling.

Loaded strictly from TOML (`configs/traffic/default.toml`) with `diffsense.config`; every range is
an interval `[lo, hi]` drawn uniformly, per simulation (density, speed level) or per vehicle (sizes,
IDM parameters, politeness, lane-change duration). Domain checks raise `InputError` naming the key.
"""

from __future__ import annotations

import dataclasses
import math

from diffsense.runtime import InputError

Interval = tuple[float, float]
# Shortest ring road: twice the social grid's reach (2 x 90 ft = 54.9 m) and a margin, so that no
# vehicle is ever within the grid both ahead and behind.
MIN_RING_M = 60.0


def _check_interval(where: str, value: Interval, lo: float = -math.inf, hi: float = math.inf, positive: bool = False) -> None:
    a, b = value
    if a > b:
        raise InputError(f"{where}: reversed interval [{a}, {b}] (need lo <= hi)")
    if positive and a <= 0.0:
        raise InputError(f"{where}: must be > 0, got [{a}, {b}]")
    if a < lo or b > hi:
        raise InputError(f"{where}: [{a}, {b}] is outside the allowed range [{lo}, {hi}]")


def _check_positive(where: str, value: float) -> None:
    if not value > 0.0:
        raise InputError(f"{where}: must be > 0, got {value}")


@dataclasses.dataclass(frozen=True)
class RingRoadConfig:
    """A straight multi-lane road closed into a ring, so that density stays constant.

    Attributes:
        num_lanes: lanes, 0 = rightmost [-].
        lane_width_m: lane width [m].
        vehicles_per_lane: vehicles placed per lane; the ring length follows from the density [-].
    """

    num_lanes: int = 4
    lane_width_m: float = 3.66
    vehicles_per_lane: int = 10

    def __post_init__(self):
        if not 1 <= self.num_lanes <= 8:
            raise InputError(f"road.num_lanes: must be in 1..8, got {self.num_lanes}")
        _check_positive("road.lane_width_m", self.lane_width_m)
        if not 2 <= self.vehicles_per_lane <= 64:
            raise InputError(f"road.vehicles_per_lane: must be in 2..64, got {self.vehicles_per_lane}")


@dataclasses.dataclass(frozen=True)
class KindConfig:
    """Size and IDM parameter ranges of one vehicle kind (drawn per vehicle).

    Attributes:
        length_m, width_m: body size [m].
        max_desired_speed_mps: cap on the driver's desired speed (trucks are limited) [m/s].
        time_headway_s: IDM T [s].
        min_gap_m: IDM s0 [m].
        max_accel_mps2: IDM a_max [m/s2].
        comfort_decel_mps2: IDM b [m/s2].
    """

    length_m: Interval = (4.0, 5.0)
    width_m: Interval = (1.7, 1.9)
    max_desired_speed_mps: float = 45.0
    time_headway_s: Interval = (1.0, 1.8)
    min_gap_m: Interval = (1.5, 2.5)
    max_accel_mps2: Interval = (1.0, 1.8)
    comfort_decel_mps2: Interval = (1.5, 2.5)

    def check(self, where: str, lane_width_m: float) -> None:
        _check_interval(f"{where}.length_m", self.length_m, hi=30.0, positive=True)
        _check_interval(f"{where}.width_m", self.width_m, hi=lane_width_m, positive=True)
        _check_positive(f"{where}.max_desired_speed_mps", self.max_desired_speed_mps)
        _check_interval(f"{where}.time_headway_s", self.time_headway_s, positive=True)
        _check_interval(f"{where}.min_gap_m", self.min_gap_m, positive=True)
        _check_interval(f"{where}.max_accel_mps2", self.max_accel_mps2, positive=True)
        _check_interval(f"{where}.comfort_decel_mps2", self.comfort_decel_mps2, positive=True)


@dataclasses.dataclass(frozen=True)
class TrafficRanges:
    """Per-simulation traffic state and driver heterogeneity.

    Attributes:
        density_veh_per_km_lane: traffic density, drawn per simulation [veh/km/lane].
        desired_speed_mps: the simulation's mean desired speed, drawn per simulation [m/s].
        desired_speed_spread: each driver's desired speed is the mean times U(1 - x, 1 + x) [-].
        speed_change_rate_per_s: rate of a driver redrawing its desired speed [1/s].
        speed_change_factor: a redrawn desired speed is the mean times U(lo, hi): slow-downs
            (a queue ahead, a merging truck) make the braking manoeuvres [-].
        kind_probabilities: probabilities of car, van, truck [-].
        accel_exponent: IDM delta, the same for all drivers [-].
    """

    density_veh_per_km_lane: Interval = (12.0, 55.0)
    desired_speed_mps: Interval = (22.0, 33.0)
    desired_speed_spread: float = 0.2
    speed_change_rate_per_s: float = 0.05
    speed_change_factor: Interval = (0.2, 1.2)
    kind_probabilities: tuple[float, float, float] = (0.8, 0.12, 0.08)
    accel_exponent: float = 4.0

    def __post_init__(self):
        _check_interval("traffic.density_veh_per_km_lane", self.density_veh_per_km_lane, hi=150.0, positive=True)
        _check_interval("traffic.desired_speed_mps", self.desired_speed_mps, hi=60.0, positive=True)
        if not 0.0 <= self.desired_speed_spread < 1.0:
            raise InputError(f"traffic.desired_speed_spread: must be in [0, 1), got {self.desired_speed_spread}")
        if self.speed_change_rate_per_s < 0.0:
            raise InputError(f"traffic.speed_change_rate_per_s: must be >= 0, got {self.speed_change_rate_per_s}")
        _check_interval("traffic.speed_change_factor", self.speed_change_factor, hi=3.0, positive=True)
        p = self.kind_probabilities
        if min(p) < 0.0 or abs(sum(p) - 1.0) > 1e-6:
            raise InputError(f"traffic.kind_probabilities: must be >= 0 and sum to 1, got {list(p)}")
        _check_positive("traffic.accel_exponent", self.accel_exponent)


@dataclasses.dataclass(frozen=True)
class LaneChangeConfig:
    """MOBIL decisions and the quintic lateral manoeuvre.

    Attributes:
        duration_s: lane-change duration, drawn per manoeuvre [s].
        politeness: MOBIL p, drawn per driver [-].
        threshold_mps2: MOBIL a_th [m/s2].
        safe_decel_mps2: MOBIL b_safe [m/s2].
        keep_right_bias_mps2: extra advantage needed to move left [m/s2].
        min_gap_m: both bumper gaps in the new lane must exceed this to start [m].
        cooldown_s: time after a lane change before the next one may start [s].
        route_change_rate_per_s: rate of a driver picking a new preferred lane (its route) [1/s].
        route_bias_mps2: MOBIL incentive added towards the preferred lane, removed away from it [m/s2].
        conflict_distance_m: two vehicles starting into a common lane in the same step closer
            than this (bumper to bumper) would not have seen each other: only one may go [m].
    """

    duration_s: Interval = (3.0, 6.0)
    politeness: Interval = (0.0, 0.3)
    threshold_mps2: float = 0.1
    safe_decel_mps2: float = 3.0
    keep_right_bias_mps2: float = 0.1
    min_gap_m: float = 1.0
    cooldown_s: float = 4.0
    conflict_distance_m: float = 30.0
    route_change_rate_per_s: float = 0.1
    route_bias_mps2: float = 1.5

    def __post_init__(self):
        _check_interval("lane_change.duration_s", self.duration_s, positive=True)
        _check_interval("lane_change.politeness", self.politeness, lo=0.0)
        _check_positive("lane_change.safe_decel_mps2", self.safe_decel_mps2)
        for name in ("min_gap_m", "cooldown_s", "conflict_distance_m", "route_change_rate_per_s", "route_bias_mps2"):
            if getattr(self, name) < 0.0:
                raise InputError(f"lane_change.{name}: must be >= 0, got {getattr(self, name)}")


@dataclasses.dataclass(frozen=True)
class SamplingConfig:
    """Time line of one simulation and how many samples it yields.

    Attributes:
        warmup_s: simulated before anything is recorded, to forget the initial placement [s].
        window_s: span of the prediction instants (one every `instant_every_s`) [s].
        instant_every_s: time between two prediction instants of the same vehicle [s].
        simulations_per_shard: simulations run in one vectorised batch; one shard each [-].
        num_samples: samples to generate (the CLI's --samples overrides it) [-].
        seed: the dataset's PRNG seed (the CLI's --seed overrides it) [-].
    """

    warmup_s: float = 20.0
    window_s: float = 40.0
    instant_every_s: float = 1.0
    simulations_per_shard: int = 32
    num_samples: int = 1_000_000
    seed: int = 0

    def __post_init__(self):
        if self.warmup_s < 0.0:
            raise InputError(f"sampling.warmup_s: must be >= 0, got {self.warmup_s}")
        _check_positive("sampling.window_s", self.window_s)
        if not (self.instant_every_s >= 0.2 and _is_multiple(self.instant_every_s, 0.2)):
            raise InputError(f"sampling.instant_every_s: must be a positive multiple of 0.2 s, got {self.instant_every_s}")
        if not _is_multiple(self.warmup_s, 0.2) or not _is_multiple(self.window_s, 0.2):
            raise InputError("sampling.warmup_s and sampling.window_s must be multiples of 0.2 s (5 Hz)")
        if not 1 <= self.simulations_per_shard <= 4096:
            raise InputError(f"sampling.simulations_per_shard: must be in 1..4096, got {self.simulations_per_shard}")
        if self.num_samples < 1:
            raise InputError(f"sampling.num_samples: must be >= 1, got {self.num_samples}")
        if not 0 <= self.seed < 2**32:
            raise InputError(f"sampling.seed: must be in 0..2**32-1, got {self.seed}")


def _is_multiple(x: float, step: float) -> bool:
    return abs(x / step - round(x / step)) < 1e-6


@dataclasses.dataclass(frozen=True)
class TrafficConfig:
    """Everything the training-traffic generator needs (see configs/traffic/default.toml)."""

    road: RingRoadConfig = RingRoadConfig()
    traffic: TrafficRanges = TrafficRanges()
    car: KindConfig = KindConfig()
    van: KindConfig = KindConfig(length_m=(5.0, 6.0), width_m=(1.9, 2.1), max_accel_mps2=(0.8, 1.4))
    truck: KindConfig = KindConfig(
        length_m=(10.0, 16.0), width_m=(2.4, 2.6), max_desired_speed_mps=25.0, time_headway_s=(1.5, 2.2),
        min_gap_m=(2.0, 3.0), max_accel_mps2=(0.4, 0.8), comfort_decel_mps2=(1.0, 2.0),
    )
    lane_change: LaneChangeConfig = LaneChangeConfig()
    sampling: SamplingConfig = SamplingConfig()

    def __post_init__(self):
        for name in ("car", "van", "truck"):
            getattr(self, name).check(name, self.road.lane_width_m)
        shortest = self.road.vehicles_per_lane * 1000.0 / self.traffic.density_veh_per_km_lane[1]
        if shortest < MIN_RING_M:
            raise InputError(
                f"road.vehicles_per_lane: {self.road.vehicles_per_lane} vehicles at "
                f"{self.traffic.density_veh_per_km_lane[1]} veh/km make a {shortest:.0f} m ring, shorter than "
                f"{MIN_RING_M:.0f} m (the social grid would see a vehicle around the ring): add vehicles"
            )

    @property
    def kinds(self) -> tuple[KindConfig, KindConfig, KindConfig]:
        """Kind configs in the order of `diffsense.scene.CAR, VAN, TRUCK`."""
        return (self.car, self.van, self.truck)

    @property
    def num_vehicles(self) -> int:
        return self.road.num_lanes * self.road.vehicles_per_lane
