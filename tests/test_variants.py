"""Scenario variants pinned to the scenario files by hand: the nominal variant's start state
worked out from sc01's numbers, the placement rules of ScenarioConfig's docstring (bumper to
bumper gaps, the adjacent vehicle centre to centre), the background's rows and lanes, and the
randomised variants' draws (inside their ranges, uniform, each from its own key).

Sizes [m] (configs/scenarios/common/vehicles.toml): car 4.6 x 1.8, van 5.5 x 2.0, truck 12 x 2.5.
US-101's lanes are 3.66 m wide, lane 0 the rightmost: lane k's centre is at d = (k + 0.5) 3.66 m.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense import scene
from diffsense.config import replace

LENGTH = {"car": 4.6, "van": 5.5, "truck": 12.0}
WIDTH = {"car": 1.8, "van": 2.0, "truck": 2.5}
KIND_ID = {"car": 0, "van": 1, "truck": 2}
LANE_M = 3.66
_plans = jax.jit(jax.vmap(scene.draw_plan, in_axes=(None, 0, 0)))


def _numbers(cfg, dtype=jnp.float64):
    return scene.scenario_numbers(cfg, scene.load_vehicle_models(), scene.load_road(cfg.road), dtype)


def _draw(cfg, count: int, nominal: bool, seed: int = 0):
    keys = jax.random.split(jax.random.key(seed), count)
    plan = _plans(_numbers(cfg), keys, jnp.full((count,), nominal))
    return jax.tree.map(np.asarray, plan)


def test_sc01s_nominal_variant_worked_out_by_hand():
    p = jax.tree.map(lambda a: a[0], _draw(scene.load_scenario("sc01"), 1, True))
    kmh = 1.0 / 3.6
    # ego: centre at 60 m, 55 km/h, lane 2. lead (car): 45 m from the ego's front (62.3) to its
    # rear. target (car): 6 m ahead of the ego's front, from lane 3 into lane 2. target lead
    # (van): 20 m from the target's front (72.9). adjacent (truck): 8 m behind the target, lane 4.
    np.testing.assert_allclose(p.s_m, [60.0, 70.6, 109.6, 95.65, 62.6], rtol=0, atol=1e-12)
    np.testing.assert_allclose(p.speed_mps, np.array([55.0, 60.0, 55.0, 60.0, 60.0]) * kmh, rtol=1e-15)
    np.testing.assert_allclose(p.d_from_m, np.array([2.5, 3.5, 2.5, 3.5, 4.5]) * LANE_M, rtol=1e-15)
    np.testing.assert_allclose(p.d_to_m, np.array([2.5, 2.5, 2.5, 3.5, 4.5]) * LANE_M, rtol=1e-15)
    assert p.lc_start_s.tolist() == [scene.NO_LANE_CHANGE_S, 3.0, scene.NO_LANE_CHANGE_S, scene.NO_LANE_CHANGE_S, scene.NO_LANE_CHANGE_S]
    assert p.lc_duration_s.tolist() == [1.0, 4.5, 1.0, 1.0, 1.0]
    assert p.length_m.tolist() == [4.6, 4.6, 4.6, 5.5, 12.0] and p.width_m.tolist() == [1.8, 1.8, 1.8, 2.0, 2.5]
    assert p.kind.tolist() == [0, 0, 0, 1, 2] and p.role.tolist() == [0, 1, 2, 3, 4]
    assert p.kind.dtype == p.role.dtype == np.int32
    assert scene.NO_LANE_CHANGE_S <= -1e5  # a lane change that ended long before any scene starts


def _by_the_rules(cfg, ego_s: float, kinds, gap_t, gap_l, gap_tl, off_adj) -> list[float]:
    """Centres of ego, target, lead, target lead and adjacent from the ego's start, the kinds and
    the gaps, by ScenarioConfig's placement rules."""
    names = {v: k for k, v in KIND_ID.items()}
    h = [0.5 * LENGTH[names[int(k)]] for k in kinds]
    lead = ego_s + h[0] + gap_l + h[2]
    front = lead + h[2] if cfg.target_ahead_of == "lead" else ego_s + h[0]
    target = front + gap_t + h[1]
    return [ego_s, target, lead, target + h[1] + gap_tl + h[3], target + off_adj]


def test_nominal_positions_follow_the_placement_rules():
    cfg = scene.load_scenario("sc03")  # the target ahead of the lead (sc01's: above)
    p = jax.tree.map(lambda a: a[0], _draw(cfg, 1, True))
    assert p.s_m[0] == cfg.ego.s_m.nominal
    gaps = [s.position_m.nominal for s in (cfg.target, cfg.lead, cfg.target_lead, cfg.adjacent)]
    np.testing.assert_allclose(p.s_m, _by_the_rules(cfg, cfg.ego.s_m.nominal, p.kind, *gaps), rtol=0, atol=1e-12)
    lanes = [cfg.ego.lane, cfg.target_lane, cfg.ego.lane, cfg.target_lane, cfg.adjacent_lane]
    np.testing.assert_allclose(p.d_from_m, (np.array(lanes) + 0.5) * LANE_M, rtol=1e-15)
    kinds = [cfg.ego.kind] + [s.kind for s in (cfg.target, cfg.lead, cfg.target_lead, cfg.adjacent)]
    assert p.kind.tolist() == [KIND_ID[k] for k in kinds]


class _Drawn:
    """K randomised variants of a scenario and the gaps and speeds they drew, recovered from the
    start state by the placement rules (kinds drawn too)."""

    def __init__(self, cfg, count: int = 4000):
        p = _draw(cfg, count, False, seed=3)
        self.cfg, self.p, self.count = cfg, p, count
        half = np.vectorize({i: 0.5 * LENGTH[k] for k, i in KIND_ID.items()}.get)(p.kind)
        s = p.s_m
        self.gap_l = s[:, 2] - half[:, 2] - s[:, 0] - half[:, 0]
        front = s[:, 2] + half[:, 2] if cfg.target_ahead_of == "lead" else s[:, 0] + half[:, 0]
        self.gap_t = s[:, 1] - half[:, 1] - front
        self.gap_tl = s[:, 3] - half[:, 3] - s[:, 1] - half[:, 1]
        self.off_adj = s[:, 4] - s[:, 1]
        self.rel_kmh = (p.speed_mps[:, 1:] - p.speed_mps[:, :1]) * 3.6


@pytest.fixture(scope="module")
def sc03_drawn():
    return _Drawn(scene.load_scenario("sc03"))


def _uniform(x, lo, hi, count):
    """x inside [lo, hi] and its mean and variance those of U(lo, hi), within 4 standard errors."""
    x = np.asarray(x, np.float64)
    assert x.min() >= lo - 1e-9 and x.max() <= hi + 1e-9
    mean, var = 0.5 * (lo + hi), (hi - lo) ** 2 / 12.0
    assert abs(x.mean() - mean) <= 4.0 * np.sqrt(var / count) + 1e-12
    if hi > lo:
        assert abs(x.var() / var - 1.0) <= 4.0 * np.sqrt(0.8 / count)  # var of (u - 1/2)^2 scaled: 4/5
        assert x.min() < lo + 0.01 * (hi - lo) and x.max() > hi - 0.01 * (hi - lo)


def test_random_variants_draw_every_range_uniformly(sc03_drawn):
    d, cfg, k = sc03_drawn, sc03_drawn.cfg, sc03_drawn.count
    _uniform(d.p.s_m[:, 0], cfg.ego.s_m.low, cfg.ego.s_m.high, k)
    _uniform(d.p.speed_mps[:, 0] * 3.6, cfg.ego.speed_kmh.low, cfg.ego.speed_kmh.high, k)
    for x, spec in [(d.gap_t, cfg.target), (d.gap_l, cfg.lead), (d.gap_tl, cfg.target_lead), (d.off_adj, cfg.adjacent)]:
        _uniform(x, spec.position_m.low, spec.position_m.high, k)
    for i, spec in enumerate([cfg.target, cfg.lead, cfg.target_lead, cfg.adjacent]):
        _uniform(d.rel_kmh[:, i], spec.relative_speed_kmh.low, spec.relative_speed_kmh.high, k)
    _uniform(d.p.lc_start_s[:, 1], cfg.lane_change.start_s.low, cfg.lane_change.start_s.high, k)
    _uniform(d.p.lc_duration_s[:, 1], cfg.lane_change.duration_s.low, cfg.lane_change.duration_s.high, k)
    # The others never change lanes; every variant keeps the lanes of the config.
    assert np.all(d.p.lc_start_s[:, [0, 2, 3, 4]] == scene.NO_LANE_CHANGE_S) and np.all(d.p.lc_duration_s[:, [0, 2, 3, 4]] == 1)
    assert np.all(d.p.d_from_m == d.p.d_from_m[0]) and np.all(d.p.d_to_m == d.p.d_to_m[0])


def test_random_variants_draw_each_roles_kind_uniformly_from_its_list(sc03_drawn):
    d, cfg, k = sc03_drawn, sc03_drawn.cfg, sc03_drawn.count
    allowed = [(cfg.ego.kind,)] + [tuple(s.random_kinds) for s in (cfg.target, cfg.lead, cfg.target_lead, cfg.adjacent)]
    assert any(len(a) > 1 for a in allowed)
    for role, kinds in enumerate(allowed):
        ids = sorted(KIND_ID[n] for n in kinds)
        counts = np.array([(d.p.kind[:, role] == i).sum() for i in ids])
        assert counts.sum() == k  # nothing outside the list
        share = 1.0 / len(ids)
        assert np.all(np.abs(counts / k - share) <= 4.0 * np.sqrt(share * (1 - share) / k) + 1e-12)
    names = {i: n for n, i in KIND_ID.items()}
    for v in range(5):  # each body is its kind's
        np.testing.assert_array_equal(d.p.length_m[:, v], [LENGTH[names[int(i)]] for i in d.p.kind[:, v]])
        np.testing.assert_array_equal(d.p.width_m[:, v], [WIDTH[names[int(i)]] for i in d.p.kind[:, v]])


def test_each_quantity_draws_from_its_own_key(sc03_drawn):
    """Two quantities drawn from one key (the same uniforms) would be perfectly correlated."""
    d = sc03_drawn
    u = {
        "ego_s": d.p.s_m[:, 0], "ego_v": d.p.speed_mps[:, 0], "gap_t": d.gap_t, "gap_l": d.gap_l,
        "gap_tl": d.gap_tl, "off_adj": d.off_adj, "lc_start": d.p.lc_start_s[:, 1],
        "lc_duration": d.p.lc_duration_s[:, 1], "kind_lead": d.p.kind[:, 2].astype(float),
        **{f"rel{i}": d.rel_kmh[:, i] for i in range(4) if np.ptp(d.rel_kmh[:, i]) > 1e-9},
    }
    names = list(u)
    corr = np.corrcoef(np.stack([u[n] for n in names]))
    off = corr[~np.eye(len(names), dtype=bool)]
    assert np.max(np.abs(off)) < 5.0 / np.sqrt(d.count), names


@pytest.fixture(scope="module")
def with_background():
    cfg = replace(scene.load_scenario("sc01"), background={"count": 14, "relative_speed_kmh": {"nominal": 2.0,
                                                                                         "low": -10.0, "high": 10.0}})
    return cfg, _draw(cfg, 1, True), _draw(cfg, 3000, False, seed=5)


def test_background_rows_and_lanes_behind_the_ego(with_background):
    _, nominal, _ = with_background
    p = jax.tree.map(lambda a: a[0], nominal)
    assert p.s_m.shape == (19,)
    i = np.arange(14)
    lane, row = i % 6, i // 6  # US-101 has 6 lanes
    ego_rear = 60.0 - 2.3
    np.testing.assert_allclose(p.s_m[5:], ego_rear - 150.0 - 2.3 - 40.0 * row, rtol=0, atol=1e-12)
    np.testing.assert_allclose(p.d_from_m[5:], (lane + 0.5) * LANE_M, rtol=1e-15)
    np.testing.assert_array_equal(p.d_to_m[5:], p.d_from_m[5:])
    np.testing.assert_allclose(p.speed_mps[5:], (55.0 + 2.0) / 3.6, rtol=1e-15)
    assert np.all(p.lc_start_s[5:] == scene.NO_LANE_CHANGE_S) and np.all(p.lc_duration_s[5:] == 4.0)
    assert np.all(p.length_m[5:] == 4.6) and np.all(p.width_m[5:] == 1.8)
    assert np.all(p.kind[5:] == 0) and np.all(p.role[5:] == scene.BACKGROUND)
    assert p.kind.dtype == p.role.dtype == np.int32


def test_background_speeds_are_drawn_per_vehicle(with_background):
    _, _, drawn = with_background
    rel = (drawn.speed_mps[:, 5:] - drawn.speed_mps[:, :1]) * 3.6  # [K, 14]
    _uniform(rel.ravel(), -10.0, 10.0, rel.size)
    corr = np.corrcoef(rel.T)
    assert np.max(np.abs(corr[~np.eye(14, dtype=bool)])) < 5.0 / np.sqrt(rel.shape[0])
    ego_rear = drawn.s_m[:, 0] - 0.5 * drawn.length_m[:, 0]
    np.testing.assert_allclose(drawn.s_m[:, 5], ego_rear - 150.0 - 2.3, rtol=0, atol=1e-9)


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_numbers_are_arrays_in_the_type_asked_for(dtype):
    cfg = replace(scene.load_scenario("sc01"), background={"count": 3})
    nums = _numbers(cfg, dtype)
    for name in ("ego_s_m", "ego_speed_mps", "position_m", "relative_speed_mps", "d_m", "length_of",
                 "background_gap_m", "background_d_m", "background_row", "background_lane_change_s"):
        assert getattr(nums, name).dtype == dtype, name
    assert nums.nominal_kind.dtype == nums.background_kind.dtype == jnp.int32
    assert nums.allowed_kind.dtype == nums.target_ahead_of_lead.dtype == jnp.bool_
    np.testing.assert_allclose(nums.ego_speed_mps, np.array([55.0, 45.0, 65.0]) / 3.6, rtol=1e-7)
    assert nums.allowed_kind.tolist() == [[True, False, False], [True, True, False], [True, True, True],
                                          [True, True, True], [True, True, True]]
    assert not bool(nums.target_ahead_of_lead) and nums.background_row.tolist() == [0.0, 0.0, 0.0]
    # the lane centres, worked out in numpy, carry the bits JAX computes them with: in the road's
    # float type (float64 here), then cast
    lanes = np.array([2, 3, 2, 3, 4])
    np.testing.assert_array_equal(nums.d_m, ((lanes + 0.5) * 3.66).astype(dtype))
    road = scene.load_road("us101")
    np.testing.assert_array_equal(nums.d_m, np.asarray(scene.lane_centre_d_m(road, jnp.asarray(lanes))).astype(dtype))


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_a_traced_lane_width_gives_the_same_numbers(dtype):
    cfg = replace(scene.load_scenario("sc01"), background={"count": 8})
    models, road = scene.load_vehicle_models(), scene.load_road("us101")
    plain = scene.scenario_numbers(cfg, models, road, dtype)
    with_width = lambda w: scene.scenario_numbers(cfg, models, dataclasses.replace(road, lane_width_m=w), dtype)
    traced = jax.jit(with_width)(road.lane_width_m)
    for a, b in zip(jax.tree.leaves(plain), jax.tree.leaves(traced)):
        assert a.dtype == b.dtype
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    wider = jax.jit(with_width)(jnp.asarray(4.0))
    np.testing.assert_allclose(wider.d_m, (np.array([2, 3, 2, 3, 4]) + 0.5) * 4.0, rtol=1e-15)
    np.testing.assert_allclose(wider.background_d_m, (np.arange(8) % 6 + 0.5) * 4.0, rtol=1e-15)


@pytest.mark.parametrize("background", [0, 4])
def test_a_float32_plan_stays_float32(background):
    cfg = replace(scene.load_scenario("sc01"), background={"count": background})
    keys = jax.random.split(jax.random.key(0), 2)
    plan = _plans(_numbers(cfg, jnp.float32), keys, jnp.array([True, False]))
    for name in ("s_m", "speed_mps", "d_from_m", "d_to_m", "lc_start_s", "lc_duration_s", "length_m", "width_m"):
        assert getattr(plan, name).dtype == jnp.float32, name
        assert getattr(plan, name).shape == (2, 5 + background), name
    assert plan.kind.dtype == plan.role.dtype == jnp.int32


def test_a_target_ahead_of_the_ego_is_placed_from_the_egos_front_whatever_its_kind():
    # sc01's target draws car or van; its rear is position_m ahead of the ego's front.
    d = _Drawn(scene.load_scenario("sc01"), count=1000)
    assert set(np.unique(d.p.kind[:, 1])) == {KIND_ID["car"], KIND_ID["van"]}
    _uniform(d.gap_t, d.cfg.target.position_m.low, d.cfg.target.position_m.high, d.count)


def test_a_float32_roads_lane_centres_carry_the_bits_jax_computes():
    # On a float32 road JAX computes a lane centre in float32, (k + 0.5) * 3.66f, which is not the
    # float64 product rounded to float32 for lanes 2 and 4 (9.1499996 against 9.1500006).
    road = jax.tree.map(lambda a: a.astype(jnp.float32) if jnp.issubdtype(a.dtype, jnp.floating) else a,
                        scene.load_road("us101"))
    cfg = replace(scene.load_scenario("sc01"), background={"count": 6})
    nums = scene.scenario_numbers(cfg, scene.load_vehicle_models(), road, jnp.float32)
    lanes = np.array([2, 3, 2, 3, 4])
    np.testing.assert_array_equal(nums.d_m, np.asarray(scene.lane_centre_d_m(road, jnp.asarray(lanes))))
    np.testing.assert_array_equal(nums.background_d_m, np.asarray(scene.lane_centre_d_m(road, jnp.arange(6))))
    assert not np.array_equal(nums.d_m, ((lanes + 0.5) * 3.66).astype(np.float32))
