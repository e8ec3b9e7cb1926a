"""Scenario simulation: the paper's six scenarios and their randomised variants."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.config import default_text, replace
from diffsense.runtime._errors import InputError
from diffsense.scene import (
    ADJACENT,
    EGO,
    LEAD,
    SCENE_DT_S,
    TARGET,
    TARGET_LEAD,
    list_scenarios,
    load_road,
    load_scenario,
    load_vehicle_models,
    simulate_scenario,
)
from diffsense.scene._simulate import leaders, simulate_plan
from diffsense.scene._variants import NO_LANE_CHANGE_S, VehiclePlan

NUM_VARIANTS = 24
SCENARIOS = ("sc01", "sc02", "sc03", "sc04", "sc05", "sc06")


@pytest.fixture(scope="module")
def scenes():
    """Every scenario, NUM_VARIANTS variants each (one compilation per road)."""
    return {name: simulate_scenario(load_scenario(name), NUM_VARIANTS, jax.random.key(7)) for name in SCENARIOS}


def _np(scene):
    return jax.tree.map(lambda a: np.asarray(a, np.float64) if a.dtype.kind == "f" else np.asarray(a), scene)


def _pair_gaps(sc):
    """Bumper-to-bumper gap of every pair whose bodies overlap laterally [N, T, V, V] (inf else)."""
    s, d, length, width = sc.s_m, sc.d_m, sc.length_m[:, None], sc.width_m[:, None]
    lateral = np.abs(d[..., :, None] - d[..., None, :]) < 0.5 * (width[..., :, None] + width[..., None, :])
    gap = np.abs(s[..., :, None] - s[..., None, :]) - 0.5 * (length[..., :, None] + length[..., None, :])
    eye = np.eye(s.shape[-1], dtype=bool)
    return np.where(lateral & ~eye, gap, np.inf)


def test_the_six_paper_scenarios_ship():
    assert list_scenarios() == list(SCENARIOS)
    roads = {name: load_scenario(name).road for name in SCENARIOS}
    assert roads == dict(sc01="us101", sc02="us101", sc03="us101", sc04="us101", sc05="straight", sc06="straight")
    for name in SCENARIOS:
        cfg = load_scenario(name)
        assert cfg.direction == ("right" if int(name[-1]) % 2 else "left")
        assert cfg.target_ahead_of == ("ego" if name in ("sc01", "sc02") else "lead")
        assert cfg.target.relative_speed_kmh.nominal == 5.0  # the paper's test runs


@pytest.mark.parametrize("name", SCENARIOS)
def test_shapes_roles_and_dtype(scenes, name):
    sc = scenes[name]
    t = round(load_scenario(name).duration_s / SCENE_DT_S) + 1
    assert sc.s_m.shape == (NUM_VARIANTS, t, 5) and sc.length_m.shape == (NUM_VARIANTS, 5)
    assert sc.s_m.dtype == sc.x_m.dtype == jnp.float32
    assert np.all(np.asarray(sc.role) == [EGO, TARGET, LEAD, TARGET_LEAD, ADJACENT])
    assert np.all(np.asarray(sc.present)) and sc.dt_s == SCENE_DT_S
    for leaf in jax.tree.leaves(sc):
        assert np.all(np.isfinite(np.asarray(leaf, np.float64)))


@pytest.mark.parametrize("name", SCENARIOS)
def test_no_collisions_and_on_the_road(scenes, name):
    sc = _np(scenes[name])
    assert _pair_gaps(sc).min() > 0.0
    road = load_road(load_scenario(name).road)
    half_w = 0.5 * sc.width_m[:, None, :]
    assert np.all(sc.d_m - half_w >= 0.0) and np.all(sc.d_m + half_w <= road.width_m)
    assert np.all(sc.s_m >= 0.0) and np.all(sc.s_m <= road.length_m)


@pytest.mark.parametrize("name", SCENARIOS)
def test_lane_change_is_one_lane_in_the_named_direction(scenes, name):
    cfg = load_scenario(name)
    sc = _np(scenes[name])
    width = load_road(cfg.road).lane_width_m
    moved = sc.d_m[:, -1, 1] - sc.d_m[:, 0, 1]
    sign = 1.0 if cfg.direction == "left" else -1.0
    assert np.all(np.abs(sign * moved - width) <= 0.05 * width)
    assert np.all(sc.lane[:, -1, 1] == cfg.ego.lane) and np.all(sc.lane[:, 0, 1] == cfg.target_lane)
    # Only the target changes lane, and its change lasts 3-6 s (to the frame).
    assert np.all(np.ptp(sc.d_m[:, :, [0, 2, 3, 4]], axis=1) == 0.0)
    progress = sign * (sc.d_m[:, :, 1] - sc.d_m[:, :1, 1]) / width
    lasting = ((progress > 1e-6) & (progress < 1.0 - 1e-6)).sum(axis=1) * SCENE_DT_S
    assert np.all(lasting >= 3.0 - 1.01 * SCENE_DT_S) and np.all(lasting <= 6.0 + 1.01 * SCENE_DT_S)


@pytest.mark.parametrize("name", SCENARIOS)
def test_followers_keep_the_minimum_gap_in_steady_state(scenes, name):
    sc = scenes[name]
    driver = load_vehicle_models().driver
    gap_of = jax.vmap(jax.vmap(lambda s, d, v, ln, w: leaders(s, d, v, ln, w, 0.0)[0], (0, 0, 0, None, None)))
    gap = np.asarray(gap_of(sc.s_m, sc.d_m, sc.speed_mps, sc.length_m, sc.width_m))
    steady = round(12.0 / SCENE_DT_S)  # every lane change is over by 11 s (start <= 5 s, <= 6 s long)
    assert gap[:, steady:].min() >= driver.min_gap_m


@pytest.mark.parametrize("name", SCENARIOS)
def test_nominal_starts_in_steady_state_at_the_papers_relative_velocity(scenes, name):
    cfg = load_scenario(name)
    v = np.asarray(scenes[name].speed_mps[0], np.float64)  # variant 0 [T, V]
    before = round(cfg.lane_change.start_s.low / SCENE_DT_S)
    assert np.abs(np.diff(v[: before + 1], axis=0) / SCENE_DT_S).max() < 0.1  # [m/s2]
    start = round(cfg.lane_change.start_s.nominal / SCENE_DT_S)
    assert (v[start, 1] - v[start, 0]) * 3.6 == pytest.approx(5.0, abs=0.5)  # km/h, as in the paper


def test_a_platoon_started_in_equilibrium_stays_there():
    """Five cars 50 m apart at 20 m/s: desired speeds make 50 m the IDM equilibrium gap.

    The leader's free-road interaction term (s*/1e4 m)^2 ~ 1e-5 is the only drift."""
    driver = load_vehicle_models().driver
    f = lambda v: jnp.full((5,), v, jnp.float64)  # noqa: E731
    plan = VehiclePlan(
        s_m=jnp.arange(5.0) * (50.0 + 4.6), speed_mps=f(20.0), d_from_m=f(5.49), d_to_m=f(5.49),
        lc_start_s=f(NO_LANE_CHANGE_S), lc_duration_s=f(1.0), length_m=f(4.6), width_m=f(1.8),
        kind=jnp.zeros(5, jnp.int32), role=jnp.full(5, 5, jnp.int32),
    )
    sc = jax.jit(simulate_plan, static_argnums=(2, 3))(plan, load_road("straight"), driver, 601)
    gaps = np.diff(np.asarray(sc.s_m), axis=-1) - 4.6
    assert np.allclose(gaps, 50.0, atol=0.05) and np.allclose(sc.speed_mps, 20.0, atol=1e-3)
    assert gaps.min() >= driver.min_gap_m


def test_speed_gradient_matches_finite_differences():
    """How far the ego gets in 10 s of Sc-01, against its start speed (float64)."""
    cfg = load_scenario("sc01")
    road, models = load_road(cfg.road), load_vehicle_models()
    from diffsense.scene._variants import draw_plan, scenario_numbers

    plan = draw_plan(scenario_numbers(cfg, models, road, jnp.float64), jax.random.key(0), jnp.asarray(True))

    def ego_end_s(speed):
        p = dataclasses.replace(plan, speed_mps=plan.speed_mps.at[0].set(speed))
        return simulate_plan(p, road, models.driver, 101).s_m[-1, 0]

    value_and_grad = jax.jit(jax.value_and_grad(ego_end_s))  # one compilation serves both
    v = plan.speed_mps[0]
    _, grad = value_and_grad(v)
    h = 1e-5
    fd = (value_and_grad(v + h)[0] - value_and_grad(v - h)[0]) / (2 * h)
    assert np.isfinite(grad) and abs(grad - fd) < 1e-5 * max(1.0, abs(fd))
    assert 0.0 < grad < 10.0  # starting faster gets further, less than 10 s worth of it


def test_same_seed_same_scene_bit_for_bit(scenes):
    again = simulate_scenario(load_scenario("sc01"), NUM_VARIANTS, jax.random.key(7))
    for a, b in zip(jax.tree.leaves(scenes["sc01"]), jax.tree.leaves(again)):
        assert np.array_equal(np.asarray(a), np.asarray(b))
    other = simulate_scenario(load_scenario("sc01"), NUM_VARIANTS, jax.random.key(8))
    assert np.array_equal(other.s_m[0], again.s_m[0])  # variant 0 is the nominal: seed-free
    assert not np.array_equal(other.s_m[1:], again.s_m[1:])


def test_a_variant_does_not_depend_on_how_many_are_asked_for(scenes):
    few = simulate_scenario(load_scenario("sc01"), 2, 7)  # an int seed is a key
    for a, b in zip(jax.tree.leaves(few), jax.tree.leaves(scenes["sc01"])):
        assert np.array_equal(np.asarray(a), np.asarray(b)[:2])


def test_variant_zero_is_nominal_and_the_others_randomise(scenes):
    cfg = load_scenario("sc03")
    sc = _np(scenes["sc03"])
    assert sc.speed_mps[0, 0, 0] == pytest.approx(cfg.ego.speed_kmh.nominal / 3.6, rel=1e-6)
    assert sc.s_m[0, 0, 0] == pytest.approx(cfg.ego.s_m.nominal, rel=1e-6)
    v = sc.speed_mps[:, 0, 0] * 3.6
    assert np.all((v >= cfg.ego.speed_kmh.low - 1e-3) & (v <= cfg.ego.speed_kmh.high + 1e-3))
    assert len(np.unique(v)) == NUM_VARIANTS
    rel = (sc.speed_mps[:, 0, 1] - sc.speed_mps[:, 0, 0]) * 3.6
    assert np.allclose(rel, 5.0, atol=1e-4)  # the paper's relative velocity in every variant
    assert len(np.unique(sc.kind[:, 2])) > 1  # vehicle types vary


def _write(tmp_path, text):
    path = tmp_path / "scenario.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    "edit, needle",
    [
        (('duration_s = 20.0', 'duration_s = 20.0\nspeed = 3'), "unknown key 'speed'"),
        (('[lead]', '[lead]\ncolour = "red"'), "unknown key 'lead.colour'"),
        (('target_lane = 3', 'target_lane = "3"'), "target_lane: expected an integer"),
        (('duration_s = { nominal = 4.5, low = 3.0, high = 6.0 }', 'duration_s = { nominal = 4.5, low = 3.0, high = 7.0 }'), "must lie in [3.0, 6.0]"),
        (('direction = "right"', 'direction = "left"'), "must start in lane"),
        (('kind = "van"', 'kind = "bus"'), "'bus' is not one of"),
        (('start_s = { nominal = 3.0,', 'start_s = { nominal = 9.0,'), "low <= nominal <= high"),
        (('speed_kmh = { nominal = 55.0, low = 45.0,', 'speed_kmh = { nominal = 55.0, low = 2.0,'), "moving forward"),
    ],
)
def test_config_rejects_with_one_line(tmp_path, edit, needle):
    text = default_text("scenarios/sc01.toml")
    assert edit[0] in text
    with pytest.raises(InputError) as e:
        load_scenario(_write(tmp_path, text.replace(edit[0], edit[1], 1)))
    assert needle in str(e.value) and "\n" not in str(e.value)


def test_unknown_scenario_and_bad_lanes():
    with pytest.raises(InputError, match="known: sc01, sc02, sc03, sc04, sc05, sc06"):
        load_scenario("sc07")
    cfg = load_scenario("sc05")  # the straight road has lanes 0..2
    bad = replace(cfg, ego={**dataclasses.asdict(cfg.ego), "lane": 2}, target_lane=3, adjacent_lane=1)
    with pytest.raises(InputError, match="not a lane of road 'straight'"):
        simulate_scenario(bad, 2, jax.random.key(0))
    with pytest.raises(InputError, match="num_variants"):
        simulate_scenario(cfg, 0, jax.random.key(0))


def test_standstill_and_touching_vehicles_give_finite_gradients():
    """The extremes: a vehicle at rest, a pair bumper to bumper, a lane change under way."""
    driver = load_vehicle_models().driver
    road = load_road("us101")
    f = lambda *v: jnp.array(v, jnp.float64)  # noqa: E731
    plan = VehiclePlan(
        s_m=f(100.0, 104.6, 200.0), speed_mps=f(0.0, 15.0, 20.0), d_from_m=f(5.49, 5.49, 9.15),
        d_to_m=f(5.49, 5.49, 5.49), lc_start_s=f(NO_LANE_CHANGE_S, NO_LANE_CHANGE_S, 0.5),
        lc_duration_s=f(1.0, 1.0, 3.0), length_m=f(4.6, 4.6, 4.6), width_m=f(1.8, 1.8, 1.8),
        kind=jnp.zeros(3, jnp.int32), role=jnp.full(3, 5, jnp.int32),
    )

    def total(floats):
        sc = simulate_plan(dataclasses.replace(plan, **floats), road, driver, 61)
        return sum(jnp.sum(a) for a in (sc.x_m, sc.y_m, sc.heading_rad, sc.speed_mps))

    names = ("s_m", "speed_mps", "d_from_m", "d_to_m", "lc_start_s", "lc_duration_s")
    value, grads = jax.jit(jax.value_and_grad(total))({k: getattr(plan, k) for k in names})
    assert np.isfinite(value)
    for name in names:
        assert np.all(np.isfinite(grads[name])), name


@pytest.mark.slow
@pytest.mark.parametrize("name", SCENARIOS)
def test_many_variants_stay_collision_free_and_on_the_road(name):
    """The ODD claim at scale: 512 randomised variants of each scenario."""
    cfg = load_scenario(name)
    sc = _np(simulate_scenario(cfg, 512, jax.random.key(11)))
    road = load_road(cfg.road)
    assert _pair_gaps(sc).min() > 0.0
    half_w = 0.5 * sc.width_m[:, None, :]
    assert np.all(sc.d_m - half_w >= 0.0) and np.all(sc.d_m + half_w <= road.width_m)
    assert np.all(sc.s_m >= 0.0) and np.all(sc.s_m <= road.length_m)
