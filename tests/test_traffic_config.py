"""The training-traffic config's checks at their boundaries: each limit accepted on its inside and
refused just outside, naming the key."""

from __future__ import annotations

import pytest

from diffsense import scene
from diffsense.config import replace
from diffsense.runtime import InputError

BASE = scene.TrafficConfig()

REFUSED = [
    (scene.RingRoadConfig, {"num_lanes": 0}, "road.num_lanes"),
    (scene.RingRoadConfig, {"num_lanes": 9}, "road.num_lanes"),
    (scene.RingRoadConfig, {"lane_width_m": 0.0}, "road.lane_width_m"),
    (scene.RingRoadConfig, {"vehicles_per_lane": 1}, "road.vehicles_per_lane"),
    (scene.RingRoadConfig, {"vehicles_per_lane": 65}, "road.vehicles_per_lane"),
    (scene.TrafficRanges, {"density_veh_per_km_lane": (20.0, 10.0)},
     "traffic.density_veh_per_km_lane"),
    (scene.TrafficRanges, {"density_veh_per_km_lane": (0.0, 10.0)}, "traffic.density_veh_per_km_lane"),
    (scene.TrafficRanges, {"density_veh_per_km_lane": (10.0, 150.5)},
     "traffic.density_veh_per_km_lane"),
    (scene.TrafficRanges, {"desired_speed_mps": (20.0, 60.5)},
     "traffic.desired_speed_mps"),
    (scene.TrafficRanges, {"desired_speed_mps": (0.0, 30.0)}, "traffic.desired_speed_mps"),
    (scene.TrafficRanges, {"speed_change_factor": (0.0, 1.0)}, "traffic.speed_change_factor"),
    (scene.TrafficRanges, {"desired_speed_spread": -0.1}, "traffic.desired_speed_spread"),
    (scene.TrafficRanges, {"desired_speed_spread": 1.0}, "traffic.desired_speed_spread"),
    (scene.TrafficRanges, {"speed_change_rate_per_s": -0.01}, "traffic.speed_change_rate_per_s"),
    (scene.TrafficRanges, {"speed_change_factor": (0.5, 3.5)},
     "traffic.speed_change_factor"),
    (scene.TrafficRanges, {"kind_probabilities": (0.5, 0.5, 0.01)},
     "traffic.kind_probabilities"),
    (scene.TrafficRanges, {"kind_probabilities": (1.1, -0.1, 0.0)},
     "traffic.kind_probabilities"),
    (scene.TrafficRanges, {"accel_exponent": 0.0}, "traffic.accel_exponent"),
    (scene.LaneChangeConfig, {"duration_s": (0.0, 4.0)}, "lane_change.duration_s"),
    (scene.LaneChangeConfig, {"politeness": (-0.1, 0.3)},
     "lane_change.politeness"),
    (scene.LaneChangeConfig, {"safe_decel_mps2": 0.0}, "lane_change.safe_decel_mps2"),
    *[(scene.LaneChangeConfig, {name: -0.5}, f"lane_change.{name}")
      for name in ("min_gap_m", "cooldown_s", "conflict_distance_m", "route_change_rate_per_s", "route_bias_mps2")],
    (scene.SamplingConfig, {"warmup_s": -0.2}, "sampling.warmup_s"),
    (scene.SamplingConfig, {"window_s": 0.0}, "sampling.window_s"),
    (scene.SamplingConfig, {"instant_every_s": 0.1}, "sampling.instant_every_s"),
    (scene.SamplingConfig, {"instant_every_s": 0.5}, "sampling.instant_every_s"),
    (scene.SamplingConfig, {"warmup_s": 0.3}, "sampling.warmup_s"),
    (scene.SamplingConfig, {"window_s": 1.1}, "sampling.warmup_s"),
    (scene.SamplingConfig, {"simulations_per_shard": 0}, "sampling.simulations_per_shard"),
    (scene.SamplingConfig, {"simulations_per_shard": 4097}, "sampling.simulations_per_shard"),
    (scene.SamplingConfig, {"num_samples": 0}, "sampling.num_samples"),
    (scene.SamplingConfig, {"seed": -1}, "sampling.seed"),
    (scene.SamplingConfig, {"seed": 2**32}, "sampling.seed"),
]


@pytest.mark.parametrize(("cls", "edit", "message"), REFUSED)
def test_each_check_refuses_just_outside_naming_the_key(cls, edit, message):
    with pytest.raises(InputError) as e:
        cls(**edit)
    assert str(e.value).startswith(message) and "\n" not in str(e.value)


@pytest.mark.parametrize(("cls", "edit"), [
    (scene.RingRoadConfig, {"num_lanes": 1}), (scene.RingRoadConfig, {"num_lanes": 8}),
    (scene.RingRoadConfig, {"vehicles_per_lane": 2}), (scene.RingRoadConfig, {"vehicles_per_lane": 64}),
    (scene.TrafficRanges, {"density_veh_per_km_lane": (10.0, 10.0)}), (scene.TrafficRanges, {"density_veh_per_km_lane": (1.0, 150.0)}),
    (scene.TrafficRanges, {"desired_speed_mps": (60.0, 60.0)}), (scene.TrafficRanges, {"desired_speed_spread": 0.0}),
    (scene.TrafficRanges, {"speed_change_rate_per_s": 0.0}), (scene.TrafficRanges, {"speed_change_factor": (3.0, 3.0)}),
    (scene.TrafficRanges, {"kind_probabilities": (0.0, 0.0, 1.0)}), (scene.TrafficRanges, {"kind_probabilities": (0.3, 0.3, 0.4000005)}),
    (scene.LaneChangeConfig, {"politeness": (0.0, 0.0)}),
    (scene.LaneChangeConfig, {name: 0.0 for name in ("min_gap_m", "cooldown_s", "conflict_distance_m",
                                                "route_change_rate_per_s", "route_bias_mps2")}),
    (scene.SamplingConfig, {"warmup_s": 0.0}), (scene.SamplingConfig, {"instant_every_s": 0.2}), (scene.SamplingConfig, {"instant_every_s": 0.6}),
    (scene.SamplingConfig, {"window_s": 0.2}), (scene.SamplingConfig, {"simulations_per_shard": 1}),
    (scene.SamplingConfig, {"simulations_per_shard": 4096}), (scene.SamplingConfig, {"num_samples": 1}),
    (scene.SamplingConfig, {"seed": 0}), (scene.SamplingConfig, {"seed": 2**32 - 1}),
])
def test_each_limit_is_accepted_on_its_inside(cls, edit):
    made = cls(**edit)
    for name, value in edit.items():
        assert getattr(made, name) == value


@pytest.mark.parametrize(("kind", "field", "value", "message"), [
    ("car", "length_m", (0.0, 5.0), "car.length_m"),
    ("van", "length_m", (5.0, 30.5), "van.length_m"),
    ("truck", "width_m", (2.4, 3.7), "truck.width_m"),
    ("van", "width_m", (0.0, 2.0), "van.width_m"),
    ("truck", "max_accel_mps2", (0.0, 0.5), "truck.max_accel_mps2"),
    ("car", "max_desired_speed_mps", 0.0, "car.max_desired_speed_mps"),
    ("car", "time_headway_s", (0.0, 1.0), "car.time_headway_s"),
    ("van", "min_gap_m", (-1.0, 1.0), "van.min_gap_m"),
    ("truck", "max_accel_mps2", (1.0, 0.5), "truck.max_accel_mps2"),
    ("car", "comfort_decel_mps2", (0.0, 2.0), "car.comfort_decel_mps2"),
])
def test_each_kind_is_checked_by_name_against_the_lane_width(kind, field, value, message):
    with pytest.raises(InputError) as e:
        replace(BASE, **{kind: replace(getattr(BASE, kind), **{field: value})})
    assert str(e.value).startswith(message)


def test_a_kind_may_be_as_wide_as_the_lane():
    assert replace(BASE, truck=replace(BASE.truck, width_m=(2.4, 3.66))).truck.width_m == (2.4, 3.66)


def test_a_ring_shorter_than_60_m_is_refused_by_the_vehicles_it_would_need():
    # 2 vehicles per lane at up to 40 veh/km make a 50 m ring; 3 make 75 m; at 50.04 veh/km,
    # 59.95 m.
    with pytest.raises(InputError) as e:
        replace(BASE, road=replace(BASE.road, vehicles_per_lane=2),
                traffic=replace(BASE.traffic, density_veh_per_km_lane=(10.0, 40.0)))
    assert str(e.value).startswith("road.vehicles_per_lane") and "50 m" in str(e.value)
    replace(BASE, road=replace(BASE.road, vehicles_per_lane=3), traffic=replace(BASE.traffic, density_veh_per_km_lane=(10.0, 40.0)))
    replace(BASE, road=replace(BASE.road, vehicles_per_lane=3), traffic=replace(BASE.traffic, density_veh_per_km_lane=(10.0, 50.0)))
    with pytest.raises(InputError, match="^road.vehicles_per_lane"):
        replace(BASE, road=replace(BASE.road, vehicles_per_lane=3),
                traffic=replace(BASE.traffic, density_veh_per_km_lane=(10.0, 50.04)))


def test_kinds_in_scene_order_and_the_vehicle_count():
    assert BASE.kinds[scene.CAR] is BASE.car and BASE.kinds[scene.VAN] is BASE.van and BASE.kinds[scene.TRUCK] is BASE.truck
    cfg = replace(BASE, road=replace(BASE.road, num_lanes=3, vehicles_per_lane=7))
    assert cfg.num_vehicles == 21
    assert scene.KindConfig().length_m == (4.0, 5.0)
