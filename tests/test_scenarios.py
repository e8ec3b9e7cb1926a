"""Scenario simulation: the paper's six scenarios and their randomised variants."""

from __future__ import annotations

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense import scene
from diffsense.config import default_text
from diffsense.runtime import InputError

NUM_VARIANTS = 24
SCENARIOS = ("sc01", "sc02", "sc03", "sc04", "sc05", "sc06")


@pytest.fixture(scope="module")
def scenes():
    """Every scenario, NUM_VARIANTS variants each (one compilation per road)."""
    return {name: scene.simulate_scenario(scene.load_scenario(name), NUM_VARIANTS, jax.random.key(7)) for name in SCENARIOS}


def _np(sc):
    return jax.tree.map(lambda a: np.asarray(a, np.float64) if a.dtype.kind == "f" else np.asarray(a), sc)


def _pair_gaps(sc):
    """Bumper-to-bumper gap of every pair whose bodies overlap laterally [N, T, V, V] (inf else)."""
    s, d, length, width = sc.s_m, sc.d_m, sc.length_m[:, None], sc.width_m[:, None]
    lateral = np.abs(d[..., :, None] - d[..., None, :]) < 0.5 * (width[..., :, None] + width[..., None, :])
    gap = np.abs(s[..., :, None] - s[..., None, :]) - 0.5 * (length[..., :, None] + length[..., None, :])
    eye = np.eye(s.shape[-1], dtype=bool)
    return np.where(lateral & ~eye, gap, np.inf)


def test_the_six_paper_scenarios_ship():
    assert scene.list_scenarios() == list(SCENARIOS)
    roads = {name: scene.load_scenario(name).road for name in SCENARIOS}
    assert roads == dict(sc01="us101", sc02="us101", sc03="us101", sc04="us101", sc05="straight", sc06="straight")
    for name in SCENARIOS:
        cfg = scene.load_scenario(name)
        assert cfg.direction == ("right" if int(name[-1]) % 2 else "left")
        assert cfg.target_ahead_of == ("ego" if name in ("sc01", "sc02") else "lead")
        assert cfg.target.relative_speed_kmh.nominal == 5.0  # the paper's test runs


@pytest.mark.parametrize("name", SCENARIOS)
def test_shapes_roles_and_dtype(scenes, name):
    sc = scenes[name]
    t = round(scene.load_scenario(name).duration_s / scene.SCENE_DT_S) + 1
    assert sc.s_m.shape == (NUM_VARIANTS, t, 5) and sc.length_m.shape == (NUM_VARIANTS, 5)
    assert sc.s_m.dtype == sc.x_m.dtype == jnp.float32
    assert np.all(np.asarray(sc.role) == [scene.EGO, scene.TARGET, scene.LEAD, scene.TARGET_LEAD, scene.ADJACENT])
    assert np.all(np.asarray(sc.present)) and sc.dt_s == scene.SCENE_DT_S
    for leaf in jax.tree.leaves(sc):
        assert np.all(np.isfinite(np.asarray(leaf, np.float64)))


@pytest.mark.parametrize("name", SCENARIOS)
def test_no_collisions_on_the_road_and_the_minimum_gap_in_steady_state(scenes, name):
    sc = _np(scenes[name])
    assert _pair_gaps(sc).min() > 0.0
    steady = round(12.0 / scene.SCENE_DT_S)  # every lane change is over by 11 s (start <= 5 s, <= 6 s long)
    assert _pair_gaps(sc)[:, steady:].min() >= scene.load_vehicle_models().driver.min_gap_m
    road = scene.load_road(scene.load_scenario(name).road)
    half_w = 0.5 * sc.width_m[:, None, :]
    assert np.all(sc.d_m - half_w >= 0.0) and np.all(sc.d_m + half_w <= road.width_m)
    assert np.all(sc.s_m >= 0.0) and np.all(sc.s_m <= road.length_m)


@pytest.mark.parametrize("name", SCENARIOS)
def test_lane_change_is_one_lane_in_the_named_direction(scenes, name):
    cfg = scene.load_scenario(name)
    sc = _np(scenes[name])
    width = scene.load_road(cfg.road).lane_width_m
    moved = sc.d_m[:, -1, 1] - sc.d_m[:, 0, 1]
    sign = 1.0 if cfg.direction == "left" else -1.0
    assert np.all(np.abs(sign * moved - width) <= 0.05 * width)
    assert np.all(sc.lane[:, -1, 1] == cfg.ego.lane) and np.all(sc.lane[:, 0, 1] == cfg.target_lane)
    # Only the target changes lane, and its change lasts 3-6 s (to the frame).
    assert np.all(np.ptp(sc.d_m[:, :, [0, 2, 3, 4]], axis=1) == 0.0)
    progress = sign * (sc.d_m[:, :, 1] - sc.d_m[:, :1, 1]) / width
    lasting = ((progress > 1e-6) & (progress < 1.0 - 1e-6)).sum(axis=1) * scene.SCENE_DT_S
    assert np.all(lasting >= 3.0 - 1.01 * scene.SCENE_DT_S) and np.all(lasting <= 6.0 + 1.01 * scene.SCENE_DT_S)


@pytest.mark.parametrize("name", SCENARIOS)
def test_nominal_starts_in_steady_state_at_the_papers_relative_velocity(scenes, name):
    cfg = scene.load_scenario(name)
    v = np.asarray(scenes[name].speed_mps[0], np.float64)  # variant 0 [T, V]
    before = round(cfg.lane_change.start_s.low / scene.SCENE_DT_S)
    assert np.abs(np.diff(v[: before + 1], axis=0) / scene.SCENE_DT_S).max() < 0.1  # [m/s2]
    start = round(cfg.lane_change.start_s.nominal / scene.SCENE_DT_S)
    assert (v[start, 1] - v[start, 0]) * 3.6 == pytest.approx(5.0, abs=0.5)  # km/h, as in the paper


def test_same_seed_same_scene_bit_for_bit(scenes):
    again = scene.simulate_scenario(scene.load_scenario("sc01"), NUM_VARIANTS, jax.random.key(7))
    for a, b in zip(jax.tree.leaves(scenes["sc01"]), jax.tree.leaves(again)):
        assert np.array_equal(np.asarray(a), np.asarray(b))
    other = scene.simulate_scenario(scene.load_scenario("sc01"), NUM_VARIANTS, jax.random.key(8))
    assert np.array_equal(other.s_m[0], again.s_m[0])  # variant 0 is the nominal: seed-free
    assert not np.array_equal(other.s_m[1:], again.s_m[1:])


def test_a_variant_does_not_depend_on_how_many_are_asked_for(scenes):
    few = scene.simulate_scenario(scene.load_scenario("sc01"), 2, 7)  # an int seed is a key
    for a, b in zip(jax.tree.leaves(few), jax.tree.leaves(scenes["sc01"])):
        assert np.array_equal(np.asarray(a), np.asarray(b)[:2])


def test_variant_zero_is_nominal_and_the_others_randomise(scenes):
    cfg = scene.load_scenario("sc03")
    sc = _np(scenes["sc03"])
    assert sc.speed_mps[0, 0, 0] == pytest.approx(cfg.ego.speed_kmh.nominal / 3.6, rel=1e-6)
    assert sc.s_m[0, 0, 0] == pytest.approx(cfg.ego.s_m.nominal, rel=1e-6)
    v = sc.speed_mps[:, 0, 0] * 3.6
    assert np.all((v >= cfg.ego.speed_kmh.low - 1e-3) & (v <= cfg.ego.speed_kmh.high + 1e-3))
    assert len(np.unique(v)) == NUM_VARIANTS
    rel = (sc.speed_mps[:, 0, 1] - sc.speed_mps[:, 0, 0]) * 3.6
    assert np.allclose(rel, 5.0, atol=1e-4)  # the paper's relative velocity in every variant
    assert len(np.unique(sc.kind[:, 2])) > 1  # vehicle types vary


@pytest.mark.parametrize("edit, culprit", [
    (("duration_s = 20.0", "duration_s = 20.0\nspeed = 3"), "'speed'"),
    (("[lead]", '[lead]\ncolour = "red"'), "'lead.colour'"),
    (("target_lane = 3", 'target_lane = "3"'), "target_lane"),
    (("duration_s = { nominal = 4.5, low = 3.0, high = 6.0 }", "duration_s = { nominal = 4.5, low = 3.0, high = 7.0 }"),
     "duration_s"),
    (('direction = "right"', 'direction = "left"'), "target_lane"),
    (('kind = "van"', 'kind = "bus"'), "'bus'"),
    (("start_s = { nominal = 3.0,", "start_s = { nominal = 9.0,"), "9.0"),
    (("speed_kmh = { nominal = 55.0, low = 45.0,", "speed_kmh = { nominal = 55.0, low = 2.0,"), "ego.speed_kmh"),
])
def test_a_bad_scenario_file_is_refused_in_one_line_naming_the_culprit(tmp_path, edit, culprit):
    text = default_text("scenarios/sc01.toml")
    assert edit[0] in text
    path = tmp_path / "scenario.toml"
    path.write_text(text.replace(edit[0], edit[1], 1))
    with pytest.raises(InputError, match=re.escape(culprit)) as e:
        scene.load_scenario(path)
    assert "\n" not in str(e.value)


@pytest.mark.slow
@pytest.mark.parametrize("name", SCENARIOS)
def test_many_variants_stay_collision_free_and_on_the_road(name):
    """The ODD claim at scale: 512 randomised variants of each scenario."""
    cfg = scene.load_scenario(name)
    sc = _np(scene.simulate_scenario(cfg, 512, jax.random.key(11)))
    road = scene.load_road(cfg.road)
    assert _pair_gaps(sc).min() > 0.0
    half_w = 0.5 * sc.width_m[:, None, :]
    assert np.all(sc.d_m - half_w >= 0.0) and np.all(sc.d_m + half_w <= road.width_m)
    assert np.all(sc.s_m >= 0.0) and np.all(sc.s_m <= road.length_m)
