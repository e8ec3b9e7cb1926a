"""The relevant set against its definition, written out again as plain loops over frames and
vehicles (numpy, float64), on random scenes and on cases exactly at each limit; and on simulated
scenes: what can reach the target's grid or hide it stays, far traffic goes.

The definition (diffsense.scene's `relevant_mask`): a present vehicle is kept when it is the ego
or the target; when, in some frame of the prediction instants' history windows, its lane is
within one of the target's and |s - s_target| < grid_half_length_m + margin_m; or when, in such a
frame, its body overlaps (strictly) the road-frame box from the ego (its rear to sensor_reach_m
ahead of its centre) to such a vehicle's body, widened laterally by margin_m.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense import scene
from diffsense.config import replace

T, V, N = 40, 8, 6
LANE_M = 3.66


def _window(frames, history_s, dt_s=0.1):
    if frames is None:
        return [True] * T
    back = int(round(history_s / dt_s))
    return [any(f - back <= t <= f for f in frames) for t in range(T)]


def _overlaps(lo_a, hi_a, lo_b, hi_b):
    return hi_a > lo_b and lo_a < hi_b


def _by_hand(sc: dict, frames, history_s, grid_half_length_m, sensor_reach_m, margin_m):
    """One scene's relevant set by the definition, frame by frame and vehicle by vehicle."""
    s, d, lane, present = sc["s_m"], sc["d_m"], sc["lane"], sc["present"]
    hl, hw = 0.5 * sc["length_m"], 0.5 * sc["width_m"]
    window = _window(frames, history_s)
    core = [False] * V
    for j in range(V):
        for t in range(T):
            if (window[t] and present[j] and abs(int(lane[t, j]) - int(lane[t, 1])) <= 1
                    and abs(s[t, j] - s[t, 1]) < grid_half_length_m + margin_m):
                core[j] = True
    core[1] = True
    occluder = [False] * V
    for k in range(1, V):
        for t in range(T):
            if not window[t]:
                continue
            for j in range(1, V):
                if not core[j]:
                    continue
                box_s = (min(s[t, 0] - hl[0], s[t, j] - hl[j]), max(s[t, 0] + sensor_reach_m, s[t, j] + hl[j]))
                box_d = (min(d[t, 0] - hw[0], d[t, j] - hw[j]) - margin_m,
                         max(d[t, 0] + hw[0], d[t, j] + hw[j]) + margin_m)
                if (_overlaps(*box_s, s[t, k] - hl[k], s[t, k] + hl[k])
                        and _overlaps(*box_d, d[t, k] - hw[k], d[t, k] + hw[k])):
                    occluder[k] = True
    return [bool((core[v] or occluder[v] or v == 0) and present[v]) for v in range(V)]


def _random_batch(seed: int, V: int = V) -> dict:  # noqa: N803
    """N scenes of V vehicles over T frames at 10 Hz on a straight road, some changing lanes."""
    rng = np.random.default_rng(seed)
    t = np.arange(T)[None, :, None] * 0.1
    s = rng.uniform(-60.0, 160.0, (N, 1, V)) + rng.uniform(15.0, 35.0, (N, 1, V)) * t
    s = s + np.cumsum(rng.normal(0.0, 0.05, (N, T, V)), axis=1)
    lane0 = rng.integers(0, 5, (N, 1, V))
    change = rng.integers(0, T + 10, (N, 1, V))  # frame of a lane change (none for >= T)
    lane = np.where(np.arange(T)[None, :, None] >= change, np.clip(lane0 + rng.choice([-1, 1], (N, 1, V)), 0, 4),
                    lane0)
    d = (lane + 0.5) * LANE_M + rng.uniform(-0.4, 0.4, (N, T, V))
    present = rng.uniform(size=(N, V)) < 0.85
    present[:, :2] = True
    return dict(
        s_m=s, d_m=d, x_m=rng.normal(size=(N, T, V)), y_m=rng.normal(size=(N, T, V)),
        heading_rad=rng.normal(size=(N, T, V)), road_angle_rad=rng.normal(size=(N, T, V)),
        speed_mps=rng.uniform(15.0, 35.0, (N, T, V)), lane=lane.astype(np.int32),
        length_m=rng.uniform(3.5, 12.0, (N, V)), width_m=rng.uniform(1.6, 2.6, (N, V)),
        kind=rng.integers(0, 3, (N, V)).astype(np.int32), role=np.full((N, V), scene.BACKGROUND, np.int32),
        present=present,
    )


def _scene(fields: dict) -> scene.Scene:
    return scene.Scene(**{k: jnp.asarray(v) for k, v in fields.items()})


def _one(fields: dict, n: int) -> dict:
    return {k: np.asarray(v)[n] for k, v in fields.items()}


@pytest.mark.parametrize("seed, frames, history_s, reach_m, margin_m", [
    (0, None, 3.0, 4.2, scene.MARGIN_M),
    (1, [12, 30], 1.0, 4.2, 1.1),
    (2, [39], 2.0, 60.0, 0.5),
    (3, [5, 20, 35], 0.5, 0.0, 3.0),
])
def test_random_scenes_keep_what_the_definition_keeps(seed, frames, history_s, reach_m, margin_m):
    fields = _random_batch(seed)
    grid = 29.718
    f = None if frames is None else jnp.asarray(frames)
    mask = np.asarray(scene.relevant_mask(_scene(fields), f, history_s=history_s, grid_half_length_m=grid,
                                    sensor_reach_m=reach_m, margin_m=margin_m))
    expected = [_by_hand(_one(fields, n), frames, history_s, grid, reach_m, margin_m) for n in range(N)]
    assert mask.tolist() == expected
    kept = np.asarray(expected).sum()
    assert 2 * N < kept < V * N  # neither trivially everything nor only the ego and target


def _pair(s_other: float, d_other: float, lane_other: int, *, s_target=100.0, d_target=5.5, lane_target=1,
          length=4.0, width=2.0, ego_s=-500.0, ego_d=1.83) -> dict:
    """One scene: the ego, the target and one other vehicle (the rest 2 km behind), all still.
    The ego 500 m behind the target: its box to the target ends at the target's front."""
    fields = _random_batch(0)
    one = {k: np.array(v[:1]) for k, v in fields.items()}
    one["s_m"][:] = [ego_s, s_target, s_other] + [-2000.0] * (V - 3)
    one["d_m"][:] = [ego_d, d_target, d_other] + [1.83] * (V - 3)
    one["lane"][:] = [0, lane_target, lane_other] + [0] * (V - 3)
    one["length_m"][:], one["width_m"][:] = length, width
    one["present"][:] = True
    return one


def _mask(one: dict, frames=None, **kw) -> list[bool]:
    args = dict(history_s=3.0, grid_half_length_m=30.0, sensor_reach_m=4.0, margin_m=2.0) | kw
    f = None if frames is None else jnp.asarray(frames)
    return np.asarray(scene.relevant_mask(_scene(one), f, **args))[0].tolist()


@pytest.mark.parametrize("s_other, lane_other, kept", [
    (131.75, 2, True), (132.0, 2, False), (68.25, 2, True), (68.0, 2, False),  # < half length + margin
    (110.0, 0, True), (110.0, 1, True), (110.0, 2, True), (110.0, 3, False),  # the lane and one either side
])
def test_the_grid_reaches_strictly_less_than_its_half_length_plus_the_margin_and_one_lane_aside(s_other, lane_other,
                                                                                                 kept):
    # The ego on the far side of the target from the other vehicle: no box reaches it.
    one = _pair(s_other, (lane_other + 0.5) * LANE_M, lane_other, ego_s=-500.0 if s_other > 100.0 else 500.0)
    assert _mask(one)[2] is kept
    one["present"][0, 2] = False  # an absent vehicle is never kept
    assert _mask(one) == [True, True] + [False] * (V - 2)


def test_the_default_margin_is_the_sagitta_allowance():
    # 100 m of sight line on a 1200 m bend bows by 100^2 / (8 * 1200) = 1.04 m; the default is 1.1 m.
    assert 100.0**2 / (8 * 1200.0) <= scene.MARGIN_M < 1.2
    one = _pair(100.0 + 30.0 + 1.0, 9.15, 2)
    args = dict(history_s=3.0, grid_half_length_m=30.0, sensor_reach_m=4.0)
    assert np.asarray(scene.relevant_mask(_scene(one), **args))[0, 2]
    one["s_m"][..., 2] = 100.0 + 30.0 + 1.125
    assert not np.asarray(scene.relevant_mask(_scene(one), **args))[0, 2]


@pytest.mark.parametrize("frame, kept", [(29, True), (30, True), (10, True), (9, False)])
def test_a_history_window_runs_from_history_s_before_the_instant_to_the_instant(frame, kept):
    # The other vehicle is in the grid at frame `frame` only; the instant is frame 30, 2 s back.
    one = _pair(0.0, 9.15, 2)
    one["s_m"][0, :, 2] = -1000.0
    one["s_m"][0, frame, 2] = 110.0
    assert _mask(one, [30], history_s=2.0)[2] is kept
    assert _mask(one)[2]  # no instants given: every frame counts


def test_traced_instants_give_the_same_windows():
    one = _pair(0.0, 9.15, 2)
    one["s_m"][0, :, 2] = -1000.0
    one["s_m"][0, 10, 2] = 110.0
    args = dict(history_s=2.0, grid_half_length_m=30.0, sensor_reach_m=4.0, margin_m=2.0)
    traced = jax.jit(lambda sc, f: scene.relevant_mask(sc, f, **args))
    for instant, kept in [(30, True), (31, False), (9, False)]:
        assert np.asarray(traced(_scene(one), jnp.asarray([instant])))[0, 2] == kept
        assert _mask(one, [instant], history_s=2.0)[2] is kept


# Vehicle 2 (4 m x 2 m) as a possible occluder of the target (s = 100, d = 5.5) seen from the ego
# (s = 0, d = 5.5): the box runs s in [-2, 102], d in [2.5, 8.5] (margin 2 m, reach 4 m); touching it
# is not overlapping it.
@pytest.mark.parametrize("s_k, d_k, kept, where", [
    (50.0, 5.5, True, {}),      # on the sight line
    (-3.9, 5.5, True, {}),      # rear overlaps the ego's own rear edge at s = -2 (front at -1.9)
    (-4.0, 5.5, False, {}),     # front exactly at the box's rear edge
    (103.9, 5.5, True, {}), (104.0, 5.5, False, {}),  # rear exactly at the target's front
    (50.0, 9.4, True, {}), (50.0, 9.5, False, {}),    # right side exactly on the box's left edge d = 8.5
    (50.0, 1.6, True, {}), (50.0, 1.5, False, {}),    # left side exactly on the box's right edge d = 2.5
    # a target behind the ego (s = -100): from its rear at -102 to the ego's sensors, reach ahead
    (-103.9, 8.0, True, {"s_target": -100.0}), (-104.0, 8.0, False, {"s_target": -100.0}),
    (7.0, 5.5, True, {"s_target": -100.0, "sensor_reach_m": 5.5}),  # its rear at 5.0 < 5.5
    (7.0, 5.5, False, {"s_target": -100.0, "sensor_reach_m": 5.0}),
    # the ego in lane 2 (d = 9.15), the target in lane 1 (d = 5.5): box d in [2.5, 12.15]
    (50.0, 1.6, True, {"ego_d": 9.15}), (50.0, 1.5, False, {"ego_d": 9.15}),
    (50.0, 13.1, True, {"ego_d": 9.15}), (50.0, 13.2, False, {"ego_d": 9.15}),
])
def test_an_occluder_is_a_body_strictly_overlapping_the_widened_box(s_k, d_k, kept, where):
    one = _pair(s_k, d_k, 3, ego_s=0.0, ego_d=where.get("ego_d", 5.5), s_target=where.get("s_target", 100.0))
    assert _mask(one, sensor_reach_m=where.get("sensor_reach_m", 4.0), grid_half_length_m=1.0)[2] is kept


def test_selection_keeps_the_relevant_in_order_then_pads_and_the_pads_sit_behind_the_ego():
    fields = _random_batch(2)
    args = dict(history_s=0.5, grid_half_length_m=29.718, sensor_reach_m=4.2, margin_m=3.0)
    frames = jnp.asarray([5])
    batch = _scene(fields)
    mask = np.asarray(scene.relevant_mask(batch, frames, **args))
    assert not np.array_equal(mask, np.asarray(scene.relevant_mask(batch, **args)))  # the instant matters here
    assert not np.array_equal(mask, np.asarray(scene.relevant_mask(batch, frames, **(args | {"margin_m": scene.MARGIN_M}))))
    order, keep = scene.relevant_selection(batch, frames, **args)
    width = mask.sum(axis=1).max()
    assert order.shape == keep.shape == (N, width) and width < V
    for n in range(N):
        kept = np.flatnonzero(mask[n])
        rest = np.flatnonzero(~mask[n])
        assert order[n].tolist() == (kept.tolist() + rest.tolist())[:width]
        assert keep[n].tolist() == [True] * len(kept) + [False] * (width - len(kept))
    out = scene.relevant_vehicles(batch, frames, **args)
    assert jax.tree.map(np.shape, out) == jax.tree.map(np.shape, scene.select_vehicles(batch, order, keep))
    for n in range(N):
        for slot in range(width):
            v = order[n, slot]
            for name in ("s_m", "d_m", "x_m", "y_m", "heading_rad", "road_angle_rad", "speed_mps", "lane"):
                got = np.asarray(getattr(out, name))[n, :, slot]
                ego = fields[name][n, :, 0]
                want = fields[name][n, :, v] if keep[n, slot] else {
                    "s_m": ego - 1000.0,
                    "x_m": ego - 1000.0 * np.cos(fields["road_angle_rad"][n, :, 0]),
                    "y_m": ego - 1000.0 * np.sin(fields["road_angle_rad"][n, :, 0]),
                }.get(name, ego)
                np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9, err_msg=name)
            for name in ("length_m", "width_m"):
                want = fields[name][n, v] if keep[n, slot] else fields[name][n, 0]
                assert np.asarray(getattr(out, name))[n, slot] == want
            assert np.asarray(out.kind)[n, slot] == (fields["kind"][n, v] if keep[n, slot] else scene.CAR)
            assert np.asarray(out.role)[n, slot] == (fields["role"][n, v] if keep[n, slot] else scene.BACKGROUND)
            assert bool(np.asarray(out.present)[n, slot]) is bool(keep[n, slot])


def test_one_scene_gives_one_selection_and_one_scene_back():
    fields = _one(_random_batch(2), 3)
    args = dict(history_s=3.0, grid_half_length_m=29.718, sensor_reach_m=4.2)
    batch = dataclasses.replace(_scene(fields), dt_s=0.2)  # every frame searched: dt_s changes no window
    order, keep = scene.relevant_selection(batch, **args)
    assert order.ndim == keep.ndim == 1 and keep.all()
    expected = _by_hand(fields, None, 3.0, 29.718, 4.2, scene.MARGIN_M)
    assert order.tolist() == np.flatnonzero(expected).tolist()
    out = scene.relevant_vehicles(batch, **args)
    assert out.s_m.shape == (T, int(np.sum(expected)))
    np.testing.assert_array_equal(np.asarray(out.s_m), fields["s_m"][:, order])
    traced = jax.jit(scene.select_vehicles)(batch, jnp.asarray(order), jnp.asarray(keep))
    np.testing.assert_array_equal(np.asarray(traced.d_m), fields["d_m"][:, order])
    assert out.dt_s == traced.dt_s == 0.2  # the selection keeps the scene's frame period


def test_a_long_vehicle_axis_keeps_the_relevant_in_their_order():
    # 48 vehicles: past the 16 elements below which numpy's default (unstable) sort is an
    # insertion sort, so only a stable sort keeps the kept vehicles in their order.
    fields = _random_batch(4, V=48)
    args = dict(history_s=3.0, grid_half_length_m=29.718, sensor_reach_m=4.2)
    batch = _scene(fields)
    mask = np.asarray(scene.relevant_mask(batch, **args))
    order, keep = scene.relevant_selection(batch, **args)
    assert mask.sum(axis=1).min() > 16
    for n in range(N):
        kept = np.flatnonzero(mask[n])
        assert order[n, :len(kept)].tolist() == kept.tolist() and keep[n, :len(kept)].all()
        assert not keep[n, len(kept):].any()


# The CS-LSTM's 3 s history and 13 cells of 15 ft (+-97.5 ft = 29.718 m); the radar 4.2 m ahead.
REACH = dict(history_s=3.0, grid_half_length_m=29.718, sensor_reach_m=4.2)


@pytest.fixture(scope="module")
def sc01_with_background():
    cfg = scene.load_scenario("sc01")
    plain = scene.simulate_scenario(cfg, 24, jax.random.key(7))  # test_scene.py's shapes: compiled once
    crowded = scene.simulate_scenario(replace(cfg, background={"count": 100}), 8, jax.random.key(7))
    # A variant does not depend on how many are drawn: the first 8 of `plain` are `crowded`'s.
    return jax.tree.map(lambda a: a[:8], plain), crowded


def test_far_background_costs_nothing(sc01_with_background):
    plain, crowded = sc01_with_background
    assert crowded.num_vehicles == 105
    kept_plain, kept_crowded = scene.relevant_vehicles(plain, **REACH), scene.relevant_vehicles(crowded, **REACH)
    assert kept_crowded.num_vehicles == kept_plain.num_vehicles <= 5  # padded to the batch's own max
    for field in dataclasses.fields(scene.Scene):
        a, b = np.asarray(getattr(kept_plain, field.name)), np.asarray(getattr(kept_crowded, field.name))
        if field.name in ("x_m", "y_m", "heading_rad", "road_angle_rad"):
            # The same (s, d) mapped by two compiled programs: float32 may differ in the last bit.
            assert np.allclose(a, b, rtol=0.0, atol=1e-4)
        else:
            assert np.array_equal(a, b)  # the very same vehicles, untouched
    assert np.all(np.asarray(kept_crowded.role[:, :2]) == [scene.EGO, scene.TARGET])


def test_background_changes_lanes_by_mobil_without_collisions(sc01_with_background):
    _, crowded = sc01_with_background
    s, d = np.asarray(crowded.s_m, np.float64), np.asarray(crowded.d_m, np.float64)
    length, width = np.asarray(crowded.length_m)[:, None], np.asarray(crowded.width_m)[:, None]
    lateral = np.abs(d[..., :, None] - d[..., None, :]) < 0.5 * (width[..., :, None] + width[..., None, :])
    gap = np.abs(s[..., :, None] - s[..., None, :]) - 0.5 * (length[..., :, None] + length[..., None, :])
    gap = np.where(lateral & ~np.eye(s.shape[-1], dtype=bool), gap, np.inf)
    assert gap.min() > 0.0  # no two of the 105 vehicles ever touch
    bg = d[:, :, 5:]
    assert np.any(bg[:, -1] != bg[:, 0])  # MOBIL did change lanes (speeds differ by up to 20 km/h)
    # Between lane changes a vehicle is on a lane centre: changes are whole lanes.
    resting = np.diff(bg, axis=1) == 0.0  # frame k to k + 1
    resting = np.concatenate([resting, resting[:, -1:]], axis=1)
    lanes = bg / 3.66 - 0.5
    assert np.allclose(lanes[resting], np.round(lanes[resting]), atol=1e-3)
    road = scene.load_road("us101")
    assert np.all(bg - 0.9 >= 0.0) and np.all(bg + 0.9 <= road.width_m)  # on the road (car 1.8 m wide)
