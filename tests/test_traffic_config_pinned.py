"""The training-traffic config's checks pinned at their boundaries: each limit accepted on its
inside and refused just outside, with the whole message naming the key.
"""

from __future__ import annotations

import pytest

from diffsense.config import replace
from diffsense.runtime._errors import InputError
from diffsense.scene import CAR, TRUCK, VAN
from diffsense.scene._traffic_config import (
    KindConfig,
    LaneChangeConfig,
    RingRoadConfig,
    SamplingConfig,
    TrafficConfig,
    TrafficRanges,
)

BASE = TrafficConfig()

REFUSED = [
    (RingRoadConfig, {"num_lanes": 0}, "road.num_lanes: must be in 1..8, got 0"),
    (RingRoadConfig, {"num_lanes": 9}, "road.num_lanes: must be in 1..8, got 9"),
    (RingRoadConfig, {"lane_width_m": 0.0}, "road.lane_width_m: must be > 0, got 0.0"),
    (RingRoadConfig, {"vehicles_per_lane": 1}, "road.vehicles_per_lane: must be in 2..64, got 1"),
    (RingRoadConfig, {"vehicles_per_lane": 65}, "road.vehicles_per_lane: must be in 2..64, got 65"),
    (TrafficRanges, {"density_veh_per_km_lane": (20.0, 10.0)},
     "traffic.density_veh_per_km_lane: reversed interval [20.0, 10.0] (need lo <= hi)"),
    (TrafficRanges, {"density_veh_per_km_lane": (0.0, 10.0)}, "traffic.density_veh_per_km_lane: must be > 0, got [0.0, 10.0]"),
    (TrafficRanges, {"density_veh_per_km_lane": (10.0, 150.5)},
     "traffic.density_veh_per_km_lane: [10.0, 150.5] is outside the allowed range [-inf, 150.0]"),
    (TrafficRanges, {"desired_speed_mps": (20.0, 60.5)},
     "traffic.desired_speed_mps: [20.0, 60.5] is outside the allowed range [-inf, 60.0]"),
    (TrafficRanges, {"desired_speed_mps": (0.0, 30.0)}, "traffic.desired_speed_mps: must be > 0, got [0.0, 30.0]"),
    (TrafficRanges, {"speed_change_factor": (0.0, 1.0)}, "traffic.speed_change_factor: must be > 0, got [0.0, 1.0]"),
    (TrafficRanges, {"desired_speed_spread": -0.1}, "traffic.desired_speed_spread: must be in [0, 1), got -0.1"),
    (TrafficRanges, {"desired_speed_spread": 1.0}, "traffic.desired_speed_spread: must be in [0, 1), got 1.0"),
    (TrafficRanges, {"speed_change_rate_per_s": -0.01}, "traffic.speed_change_rate_per_s: must be >= 0, got -0.01"),
    (TrafficRanges, {"speed_change_factor": (0.5, 3.5)},
     "traffic.speed_change_factor: [0.5, 3.5] is outside the allowed range [-inf, 3.0]"),
    (TrafficRanges, {"kind_probabilities": (0.5, 0.5, 0.01)},
     "traffic.kind_probabilities: must be >= 0 and sum to 1, got [0.5, 0.5, 0.01]"),
    (TrafficRanges, {"kind_probabilities": (1.1, -0.1, 0.0)},
     "traffic.kind_probabilities: must be >= 0 and sum to 1, got [1.1, -0.1, 0.0]"),
    (TrafficRanges, {"accel_exponent": 0.0}, "traffic.accel_exponent: must be > 0, got 0.0"),
    (LaneChangeConfig, {"duration_s": (0.0, 4.0)}, "lane_change.duration_s: must be > 0, got [0.0, 4.0]"),
    (LaneChangeConfig, {"politeness": (-0.1, 0.3)},
     "lane_change.politeness: [-0.1, 0.3] is outside the allowed range [0.0, inf]"),
    (LaneChangeConfig, {"safe_decel_mps2": 0.0}, "lane_change.safe_decel_mps2: must be > 0, got 0.0"),
    *[(LaneChangeConfig, {name: -0.5}, f"lane_change.{name}: must be >= 0, got -0.5")
      for name in ("min_gap_m", "cooldown_s", "conflict_distance_m", "route_change_rate_per_s", "route_bias_mps2")],
    (SamplingConfig, {"warmup_s": -0.2}, "sampling.warmup_s: must be >= 0, got -0.2"),
    (SamplingConfig, {"window_s": 0.0}, "sampling.window_s: must be > 0, got 0.0"),
    (SamplingConfig, {"instant_every_s": 0.1}, "sampling.instant_every_s: must be a positive multiple of 0.2 s, got 0.1"),
    (SamplingConfig, {"instant_every_s": 0.5}, "sampling.instant_every_s: must be a positive multiple of 0.2 s, got 0.5"),
    (SamplingConfig, {"warmup_s": 0.3}, "sampling.warmup_s and sampling.window_s must be multiples of 0.2 s (5 Hz)"),
    (SamplingConfig, {"window_s": 1.1}, "sampling.warmup_s and sampling.window_s must be multiples of 0.2 s (5 Hz)"),
    (SamplingConfig, {"simulations_per_shard": 0}, "sampling.simulations_per_shard: must be in 1..4096, got 0"),
    (SamplingConfig, {"simulations_per_shard": 4097}, "sampling.simulations_per_shard: must be in 1..4096, got 4097"),
    (SamplingConfig, {"num_samples": 0}, "sampling.num_samples: must be >= 1, got 0"),
    (SamplingConfig, {"seed": -1}, "sampling.seed: must be in 0..2**32-1, got -1"),
    (SamplingConfig, {"seed": 2**32}, f"sampling.seed: must be in 0..2**32-1, got {2**32}"),
]


@pytest.mark.parametrize(("cls", "edit", "message"), REFUSED)
def test_each_check_refuses_just_outside_with_its_whole_message(cls, edit, message):
    with pytest.raises(InputError) as e:
        cls(**edit)
    assert str(e.value) == message


@pytest.mark.parametrize(("cls", "edit"), [
    (RingRoadConfig, {"num_lanes": 1}), (RingRoadConfig, {"num_lanes": 8}),
    (RingRoadConfig, {"vehicles_per_lane": 2}), (RingRoadConfig, {"vehicles_per_lane": 64}),
    (TrafficRanges, {"density_veh_per_km_lane": (10.0, 10.0)}), (TrafficRanges, {"density_veh_per_km_lane": (1.0, 150.0)}),
    (TrafficRanges, {"desired_speed_mps": (60.0, 60.0)}), (TrafficRanges, {"desired_speed_spread": 0.0}),
    (TrafficRanges, {"speed_change_rate_per_s": 0.0}), (TrafficRanges, {"speed_change_factor": (3.0, 3.0)}),
    (TrafficRanges, {"kind_probabilities": (0.0, 0.0, 1.0)}), (TrafficRanges, {"kind_probabilities": (0.3, 0.3, 0.4000005)}),
    (LaneChangeConfig, {"politeness": (0.0, 0.0)}),
    (LaneChangeConfig, {name: 0.0 for name in ("min_gap_m", "cooldown_s", "conflict_distance_m",
                                                "route_change_rate_per_s", "route_bias_mps2")}),
    (SamplingConfig, {"warmup_s": 0.0}), (SamplingConfig, {"instant_every_s": 0.2}), (SamplingConfig, {"instant_every_s": 0.6}),
    (SamplingConfig, {"window_s": 0.2}), (SamplingConfig, {"simulations_per_shard": 1}),
    (SamplingConfig, {"simulations_per_shard": 4096}), (SamplingConfig, {"num_samples": 1}),
    (SamplingConfig, {"seed": 0}), (SamplingConfig, {"seed": 2**32 - 1}),
])
def test_each_limit_is_accepted_on_its_inside(cls, edit):
    made = cls(**edit)
    for name, value in edit.items():
        assert getattr(made, name) == value


@pytest.mark.parametrize(("kind", "field", "value", "message"), [
    ("car", "length_m", (0.0, 5.0), "car.length_m: must be > 0, got [0.0, 5.0]"),
    ("van", "length_m", (5.0, 30.5), "van.length_m: [5.0, 30.5] is outside the allowed range [-inf, 30.0]"),
    ("truck", "width_m", (2.4, 3.7), "truck.width_m: [2.4, 3.7] is outside the allowed range [-inf, 3.66]"),
    ("van", "width_m", (0.0, 2.0), "van.width_m: must be > 0, got [0.0, 2.0]"),
    ("truck", "max_accel_mps2", (0.0, 0.5), "truck.max_accel_mps2: must be > 0, got [0.0, 0.5]"),
    ("car", "max_desired_speed_mps", 0.0, "car.max_desired_speed_mps: must be > 0, got 0.0"),
    ("car", "time_headway_s", (0.0, 1.0), "car.time_headway_s: must be > 0, got [0.0, 1.0]"),
    ("van", "min_gap_m", (-1.0, 1.0), "van.min_gap_m: must be > 0, got [-1.0, 1.0]"),
    ("truck", "max_accel_mps2", (1.0, 0.5), "truck.max_accel_mps2: reversed interval [1.0, 0.5] (need lo <= hi)"),
    ("car", "comfort_decel_mps2", (0.0, 2.0), "car.comfort_decel_mps2: must be > 0, got [0.0, 2.0]"),
])
def test_each_kind_is_checked_by_name_against_the_lane_width(kind, field, value, message):
    with pytest.raises(InputError) as e:
        replace(BASE, **{kind: replace(getattr(BASE, kind), **{field: value})})
    assert str(e.value) == message


def test_a_kind_may_be_as_wide_as_the_lane():
    assert replace(BASE, truck=replace(BASE.truck, width_m=(2.4, 3.66))).truck.width_m == (2.4, 3.66)


def test_a_ring_shorter_than_60_m_is_refused_by_the_vehicles_it_would_need():
    # 2 vehicles per lane at up to 40 veh/km make a 50 m ring; 3 make 75 m; at 50.04 veh/km,
    # 59.95 m.
    with pytest.raises(InputError) as e:
        replace(BASE, road=replace(BASE.road, vehicles_per_lane=2),
                traffic=replace(BASE.traffic, density_veh_per_km_lane=(10.0, 40.0)))
    assert str(e.value) == ("road.vehicles_per_lane: 2 vehicles at 40.0 veh/km make a 50 m ring, shorter than 60 m "
                            "(the social grid would see a vehicle around the ring): add vehicles")
    replace(BASE, road=replace(BASE.road, vehicles_per_lane=3), traffic=replace(BASE.traffic, density_veh_per_km_lane=(10.0, 40.0)))
    replace(BASE, road=replace(BASE.road, vehicles_per_lane=3), traffic=replace(BASE.traffic, density_veh_per_km_lane=(10.0, 50.0)))
    with pytest.raises(InputError, match="make a 60 m ring, shorter than 60 m"):
        replace(BASE, road=replace(BASE.road, vehicles_per_lane=3),
                traffic=replace(BASE.traffic, density_veh_per_km_lane=(10.0, 50.04)))


def test_kinds_in_scene_order_and_the_vehicle_count():
    assert BASE.kinds[CAR] is BASE.car and BASE.kinds[VAN] is BASE.van and BASE.kinds[TRUCK] is BASE.truck
    cfg = replace(BASE, road=replace(BASE.road, num_lanes=3, vehicles_per_lane=7))
    assert cfg.num_vehicles == 21
    assert KindConfig().length_m == (4.0, 5.0)
