"""The scenario configs' checks at their boundaries (each limit accepted on its inside and refused
just outside, naming the culprit), their defaults, the slowest start speed worked out by hand,
the shipped driver model against its published values, and loading by name or path.
"""

from __future__ import annotations

import dataclasses

import pytest

from diffsense import scene
from diffsense.config import default_text
from diffsense.runtime import InputError

SC01 = scene.load_scenario("sc01")
R = scene.Range(0.0, 0.0, 0.0)


def _refused(make, *culprits: str) -> None:
    with pytest.raises(InputError) as e:
        make()
    assert all(c in str(e.value) for c in culprits) and "\n" not in str(e.value), str(e.value)


@pytest.mark.parametrize("nominal, low, high", [(1.0, 1.0, 1.0), (1.0, 1.0, 2.0), (2.0, 1.0, 2.0), (-3.0, -4.0, 5.0)])
def test_a_range_holds_its_nominal_between_its_bounds(nominal, low, high):
    spec = scene.Range(nominal, low, high)  # accepted: no InputError
    assert (spec.nominal, spec.low, spec.high) == (nominal, low, high)


@pytest.mark.parametrize("nominal, low, high", [(0.999, 1.0, 2.0), (2.001, 1.0, 2.0), (1.5, 2.0, 1.0)])
def test_a_range_outside_its_bounds_is_refused(nominal, low, high):
    _refused(lambda: scene.Range(nominal, low, high), f"{low}, {nominal}, {high}")


def test_a_vehicle_draws_from_at_least_one_kind():
    spec = scene.VehicleSpec(R, R)
    assert (spec.kind, spec.random_kinds) == ("car", ("car",))
    assert scene.VehicleSpec(R, R, "truck", ("van",)).random_kinds == ("van",)
    _refused(lambda: scene.VehicleSpec(R, R, "car", ()), "random_kinds")


def test_lane_change_durations_lie_in_the_band_of_real_lane_changes():
    start = scene.Range(0.0, 0.0, 1.0)
    assert scene.LaneChangeSpec(start, scene.Range(3.0, 3.0, 6.0)).duration_s.high == 6.0
    for low, high in ((2.999, 4.0), (3.0, 6.001), (2.0, 7.0)):
        _refused(lambda low=low, high=high: scene.LaneChangeSpec(start, scene.Range(low, low, high)),
                 "lane_change.duration_s", f"[{low}, {high}]")
    _refused(lambda: scene.LaneChangeSpec(scene.Range(0.0, -0.001, 1.0), scene.Range(4.0, 3.0, 5.0)),
             "lane_change.start_s")


def test_background_defaults_are_none_behind_and_far():
    assert scene.BackgroundSpec() == scene.BackgroundSpec(count=0, gap_m=150.0, spacing_m=40.0,
                                              relative_speed_kmh=scene.Range(0.0, -10.0, 10.0), kind="car",
                                              mobil=True, lane_change_duration_s=4.0)
    # sc01 leaves MOBIL and the lane-change duration to the defaults.
    assert (SC01.background.mobil, SC01.background.lane_change_duration_s) == (True, 4.0)


@pytest.mark.parametrize("changes", [{"lane_change_duration_s": 3.0}, {"lane_change_duration_s": 6.0},
                                     {"count": 0}, {"count": 10_000}, {"gap_m": 1e-9}, {"spacing_m": 1e-9}])
def test_background_limits_are_accepted_at_their_edges(changes):
    spec = scene.BackgroundSpec(**changes)
    assert all(getattr(spec, k) == v for k, v in changes.items())


@pytest.mark.parametrize("changes, message", [
    ({"lane_change_duration_s": 2.99}, "background.lane_change_duration_s"),
    ({"lane_change_duration_s": 6.01}, "background.lane_change_duration_s"),
    ({"count": -1}, "background.count"),
    ({"count": 10_001}, "background.count"),
    ({"gap_m": 0.0}, "background.gap_m"),
    ({"spacing_m": 0.0}, "background.spacing_m"),
])
def test_background_limits_are_refused_past_their_edges(changes, message):
    _refused(lambda: scene.BackgroundSpec(**changes), message)


def test_weather_is_clear_by_default_and_bounded():
    assert (scene.WeatherSpec().rain_mm_h, scene.WeatherSpec().fog_visibility_m) == (0.0, 0.0)
    for rain, fog in ((0.0, 0.0), (500.0, 1.0), (2.5, 1e6)):
        assert scene.WeatherSpec(rain, fog) == scene.WeatherSpec(rain_mm_h=rain, fog_visibility_m=fog)
    for rain in (-0.1, 500.1):
        _refused(lambda rain=rain: scene.WeatherSpec(rain, 0.0), "weather.rain_mm_h")
    for fog in (0.999, -1.0):
        _refused(lambda fog=fog: scene.WeatherSpec(0.0, fog), "weather.fog_visibility_m")


def test_the_target_starts_beside_the_ego_on_the_side_it_comes_from():
    # sc01: to the right from lane 3 into the ego's lane 2 (lane 0 is the rightmost).
    assert (SC01.direction, SC01.target_lane, SC01.ego.lane) == ("right", 3, 2)
    left = dataclasses.replace(SC01, direction="left", target_lane=1, adjacent_lane=0)
    assert left.target_lane == 1
    _refused(lambda: dataclasses.replace(SC01, direction="left"), "target_lane 3")
    _refused(lambda: dataclasses.replace(SC01, target_lane=1, adjacent_lane=0), "target_lane 1")
    for lane in (2, 3):
        _refused(lambda lane=lane: dataclasses.replace(SC01, adjacent_lane=lane), "adjacent_lane")


def test_scenario_duration_and_defaults():
    for duration in (1.0, 120.0):
        assert dataclasses.replace(SC01, duration_s=duration).duration_s == duration
    for duration in (0.99, 120.01):
        _refused(lambda duration=duration: dataclasses.replace(SC01, duration_s=duration), "duration_s")
    bare = {f.name: getattr(SC01, f.name) for f in dataclasses.fields(SC01) if f.default is dataclasses.MISSING}
    cfg = type(SC01)(**bare)
    assert (cfg.description, cfg.duration_s, cfg.background, cfg.weather) == ("", 20.0, scene.BackgroundSpec(), scene.WeatherSpec())


def _with_lows(ego_low: float, target: float, lead: float, target_lead: float, adjacent: float, background: float):
    def spec(old, low):
        return dataclasses.replace(old, relative_speed_kmh=scene.Range(max(low, 0.0), low, max(low, 0.0) + 1.0))

    ego = dataclasses.replace(SC01.ego, speed_kmh=scene.Range(ego_low + 5.0, ego_low, ego_low + 10.0))
    return dataclasses.replace(
        SC01, ego=ego, target=spec(SC01.target, target), lead=spec(SC01.lead, lead),
        target_lead=spec(SC01.target_lead, target_lead), adjacent=spec(SC01.adjacent, adjacent),
        background=dataclasses.replace(SC01.background, count=3, relative_speed_kmh=spec(SC01.background, background)
                                       .relative_speed_kmh))


@pytest.mark.parametrize("lows, slowest", [
    ((50.0, 1.0, 2.0, 3.0, 4.0, 5.0), 50.0),  # nobody slower than the ego: its lowest speed
    ((50.0, -7.0, -2.0, -3.0, -4.0, -5.0), 43.0),
    ((50.0, -1.0, -8.0, -3.0, -4.0, -5.0), 42.0),
    ((50.0, -1.0, -2.0, -9.0, -4.0, -5.0), 41.0),
    ((50.0, -1.0, -2.0, -3.0, -10.0, -5.0), 40.0),
    ((50.0, -1.0, -2.0, -3.0, -4.0, -11.0), 39.0),
])
def test_the_slowest_start_is_the_egos_lowest_speed_plus_the_lowest_relative_speed(lows, slowest):
    cfg = _with_lows(*lows)
    assert scene.slowest_start_kmh(cfg) == slowest
    scene.check_speed_offset(cfg, -slowest + 1e-6)
    _refused(lambda: scene.check_speed_offset(cfg, -slowest), f"{-slowest:g} km/h")


def test_every_vehicle_must_start_moving():
    assert scene.slowest_start_kmh(_with_lows(10.0, -1.0, -2.0, -3.0, -4.0, -9.999)) == pytest.approx(0.001)
    _refused(lambda: _with_lows(10.0, -1.0, -2.0, -3.0, -4.0, -10.0), "ego.speed_kmh.low")


def test_the_shipped_driver_model_is_the_published_highway_idm():
    """Treiber and Kesting, Traffic Flow Dynamics (2013): IDM highway values (Table 11.2) and
    MOBIL's typical ones (Sec. 14.3); the body sizes and limits are this project's choices."""
    models = scene.load_vehicle_models()
    d, m = models.driver, models.mobil
    assert (d.time_headway_s, d.min_gap_m, d.max_accel_mps2, d.comfort_decel_mps2, d.accel_exponent) == (
        1.5, 2.0, 1.0, 1.5, 4.0)
    assert (m.politeness, m.threshold_mps2, m.safe_decel_mps2) == (0.3, 0.2, 4.0)
    assert [(models.size(k).length_m, models.size(k).width_m) for k in ("car", "van", "truck")] == [
        (4.6, 1.8), (5.5, 2.0), (12.0, 2.5)]


def test_driver_and_mobil_limits():
    d, m = scene.load_vehicle_models().driver, scene.load_vehicle_models().mobil
    assert dataclasses.replace(d, follower_speed_ratio=1.0001).follower_speed_ratio == 1.0001
    _refused(lambda: dataclasses.replace(d, follower_speed_ratio=1.0), "driver.follower_speed_ratio")
    assert dataclasses.replace(d, min_time_headway_s=2.5, max_time_headway_s=2.5).min_time_headway_s == 2.5
    for low, high in ((0.0, 2.5), (2.6, 2.5)):
        _refused(lambda low=low, high=high: dataclasses.replace(d, min_time_headway_s=low, max_time_headway_s=high),
                 "min_time_headway_s")
    for period in (0.1, 10.0):
        assert dataclasses.replace(m, decision_period_s=period).decision_period_s == period
    for period in (0.0999, 10.01):
        _refused(lambda period=period: dataclasses.replace(m, decision_period_s=period), "mobil.decision_period_s")


def test_scenarios_load_by_name_or_by_path(tmp_path):
    assert scene.list_scenarios() == ["sc01", "sc02", "sc03", "sc04", "sc05", "sc06"]
    text = default_text("scenarios/sc03.toml")
    with_suffix, without = tmp_path / "mine.toml", tmp_path / "mine"
    with_suffix.write_text(text)
    without.write_text(text)
    assert scene.load_scenario(with_suffix) == scene.load_scenario(str(without)) == scene.load_scenario("sc03")
    assert scene.load_scenario("sc03").name == "sc03"
    for name in ("sc07", str(tmp_path / "missing")):  # the name, and the known ones
        _refused(lambda name=name: scene.load_scenario(name), f"'{name}'", "sc01, sc02, sc03, sc04, sc05, sc06")
    # A path ending in .toml is read as a file even when there is none: the error names the file.
    _refused(lambda: scene.load_scenario(tmp_path / "missing.toml"), str(tmp_path / "missing.toml"))
