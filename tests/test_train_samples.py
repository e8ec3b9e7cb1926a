"""Training samples: extracted from traffic constructed by hand (the social grid's cells across the
ring's seam, one vehicle per cell, histories and futures in the target's frame at the instant, the
manoeuvre labels' rules), and read back from a dataset written by hand (neighbours packed per
sample, the model frame in feet with the lateral axis to the right, SI kept beside it,
`max_samples` across shards, the split by whole simulations, the refusals by culprit)."""

from __future__ import annotations

import json
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.runtime import InputError
from diffsense.scene import IDMParams, TrafficTrajectories, TrafficVehicles
from diffsense.train import (
    BRAKING,
    KEEP,
    LAYOUT_VERSION,
    LEFT,
    NORMAL,
    RIGHT,
    extract_samples,
    lateral_label,
    load_samples,
    longitudinal_label,
    split_by_simulation,
)

LANE_W = 3.66
RING_M = 1000.0


def constructed_traffic() -> TrafficTrajectories:
    """Seven vehicles at 10 m/s for 9 s (91 frames at 10 Hz); the instant is frame 40 (t = 4 s).

    0: the target, lane 1, s = 990 + 10 t (near the ring's end).
    1: lane 2 (left), 9.2 m ahead -> cell round(9.2 / 4.572) + 6 = 8 -> grid id 0 * 13 + 8 = 8.
    2: lane 0 (right), 10 m behind -> cell -2 + 6 = 4 -> grid id 2 * 13 + 4 = 30.
    3: lane 1, 12 m ahead across the ring's seam (s wraps at 1000 m) -> grid id 13 + 9 = 22.
    4: lane 1, 40 m ahead: outside the grid (90 ft = 27.4 m).
    5: far away, changes from lane 3 to lane 2 between t = 5 s and 8 s -> lateral label right.
    6: far away in lane 0, stops at t = 4 s -> longitudinal label braking.
    """
    t = np.arange(91) * 0.1
    s = np.stack(
        [990 + 10 * t, 999.2 + 10 * t, 980 + 10 * t, 2 + 10 * t, 30 + 10 * t, 500 + 10 * t, 700 + 10 * np.minimum(t, 4.0)],
        axis=1,
    )
    lanes = np.array([1, 2, 0, 1, 1, 3, 0])
    d = np.broadcast_to((lanes + 0.5) * LANE_W, s.shape).copy()
    u = np.clip((t - 5.0) / 3.0, 0.0, 1.0)
    d[:, 5] = (3.5 - u * u * u * (10 - 15 * u + 6 * u * u)) * LANE_W
    lane = np.broadcast_to(lanes, s.shape).astype(np.int32)
    ones = jnp.ones(7, jnp.float32)
    vehicles = TrafficVehicles(
        length_m=4.5 * ones, width_m=1.8 * ones, kind=jnp.zeros(7, jnp.int32), idm=IDMParams(),
        politeness=0.2 * ones, max_desired_speed_mps=40 * ones, mean_desired_speed_mps=jnp.float32(30.0),
        ring_length_m=jnp.float32(RING_M),
    )
    f32 = lambda a: jnp.asarray(a, jnp.float32)
    return TrafficTrajectories(
        s_m=f32(s), d_m=f32(d), speed_mps=f32(np.gradient(s, 0.1, axis=0)), lane=jnp.asarray(lane),
        target_lane=jnp.asarray(lane), vehicles=vehicles,
    )


@pytest.fixture(scope="module")
def constructed():
    extract = jax.jit(extract_samples, static_argnums=(1, 2, 3))
    return jax.tree_util.tree_map(np.asarray, extract(constructed_traffic(), LANE_W, 0.0, 1.0))


def test_neighbours_land_in_their_grid_cells(constructed):
    assert constructed.hist.shape == (7, 16, 2) and constructed.nbr_hist.shape == (7, 39, 16, 2)
    assert constructed.hist.dtype == np.float32
    occupied = np.nonzero(constructed.nbr_present[0])[0]
    assert occupied.tolist() == [8, 22, 30]
    expected_now = {8: (9.2, LANE_W), 30: (-10.0, -LANE_W), 22: (12.0, 0.0)}
    for slot, (lon, lat) in expected_now.items():
        np.testing.assert_allclose(constructed.nbr_hist[0, slot, -1], (lon, lat), atol=2e-3)
        # 3 s earlier the neighbour was 30 m further back, relative to the target *at the instant*.
        np.testing.assert_allclose(constructed.nbr_hist[0, slot, 0], (lon - 30.0, lat), atol=2e-3)
    assert (constructed.nbr_hist[0][~constructed.nbr_present[0]] == 0).all()
    # Seen from vehicle 1 (lane 2), the target is one lane right, 9.2 m behind (cell -2 + 6 = 4) and
    # vehicle 3 one lane right, 2.8 m ahead (cell 1 + 6 = 7).
    assert np.nonzero(constructed.nbr_present[1])[0].tolist() == [2 * 13 + 4, 2 * 13 + 7]


def test_target_history_and_future_in_the_road_frame(constructed):
    np.testing.assert_allclose(constructed.hist[0, :, 0], np.arange(-15, 1) * 2.0, atol=2e-3)  # 10 m/s at 5 Hz
    np.testing.assert_allclose(constructed.fut[0, :, 0], np.arange(1, 26) * 2.0, atol=2e-3)
    assert (constructed.hist[0, -1] == 0).all() and (constructed.hist[0, :, 1] == 0).all()
    # The lane changer moves right: its future lateral offset reaches minus one lane width, along
    # the constructed smoothstep, point by point (t = 4.2 ... 9 s).
    u = np.clip((4.0 + 0.2 * np.arange(1, 26) - 5.0) / 3.0, 0.0, 1.0)
    np.testing.assert_allclose(constructed.fut[5, :, 1], -u**3 * (10 - 15 * u + 6 * u**2) * LANE_W, atol=1e-3)
    np.testing.assert_allclose(constructed.fut[5, -1, 1], -LANE_W, atol=1e-3)


def test_every_instant_reads_its_own_future():
    """The constructed scene one second longer (everyone keeps going): instants at 4 s and 5 s; the
    first is not at the recording's end, so a future window read one point late would show."""
    traffic = constructed_traffic()
    more = np.arange(1, 11, dtype=np.float32) * 0.1

    def extend(a, step=None):
        tail = a[-1:] if step is None else a[-1:] + more[:, None] * step
        return jnp.concatenate([a, jnp.broadcast_to(tail, (10, a.shape[1]))])

    longer = TrafficTrajectories(s_m=extend(traffic.s_m, traffic.speed_mps[-1]), d_m=extend(traffic.d_m),
                                 speed_mps=extend(traffic.speed_mps), lane=extend(traffic.lane),
                                 target_lane=extend(traffic.target_lane), vehicles=traffic.vehicles)
    got = extract_samples(longer, LANE_W, 1.0, 1.0)  # rows: instant * 7 + vehicle
    u = np.clip((4.0 + 0.2 * np.arange(1, 26) - 5.0) / 3.0, 0.0, 1.0)
    np.testing.assert_allclose(np.asarray(got.fut[5, :, 1]), -u**3 * (10 - 15 * u + 6 * u**2) * LANE_W, atol=1e-3)
    np.testing.assert_allclose(np.asarray(got.fut[7, :, 0]), np.arange(1, 26) * 2.0, atol=2e-3)


def test_of_two_vehicles_in_one_cell_the_one_nearer_its_centre_is_kept():
    """Target 0 and, in its lane, vehicles 12.5 m and 13.6 m ahead: both in cell round(x / 4.572)
    + 6 = 9 (centre 13.716 m); vehicle 2, the nearer the centre, is kept though its index is higher."""
    traffic = constructed_traffic()

    def pick(a):  # three vehicles, all in lane 1
        return a[:, [0, 3, 4]]

    t = jnp.arange(91, dtype=jnp.float32) * 0.1
    s = jnp.stack([100 + 10 * t, 112.5 + 10 * t, 113.6 + 10 * t], axis=1)
    three = TrafficTrajectories(s_m=s, d_m=pick(traffic.d_m), speed_mps=pick(traffic.speed_mps), lane=pick(traffic.lane),
                                target_lane=pick(traffic.target_lane),
                                vehicles=jax.tree_util.tree_map(lambda a: a[:3] if jnp.ndim(a) else a,
                                                                   traffic.vehicles))  # all alike
    got = extract_samples(three, LANE_W, 0.0, 1.0)
    assert np.nonzero(np.asarray(got.nbr_present[0]))[0].tolist() == [13 + 9]
    np.testing.assert_allclose(np.asarray(got.nbr_hist[0, 13 + 9, -1]), (13.6, 0.0), atol=2e-3)


def test_labels_of_the_constructed_scene(constructed):
    assert constructed.lat_label.tolist() == [KEEP, KEEP, KEEP, KEEP, KEEP, RIGHT, KEEP]
    assert constructed.lon_label.tolist() == [NORMAL] * 6 + [BRAKING]


@pytest.mark.parametrize(
    "before, now, after, label",
    [
        (1, 1, 1, KEEP), (1, 1, 2, LEFT), (1, 1, 0, RIGHT), (0, 1, 1, LEFT), (2, 1, 1, RIGHT),
        (0, 1, 0, RIGHT),  # both ways within 4 s: the reference checks "right" first
        (2, 1, 2, RIGHT),
    ],
)
def test_lateral_label_rule(before, now, after, label):
    assert int(jax.jit(lateral_label)(jnp.asarray(before), jnp.asarray(now), jnp.asarray(after))) == label


@pytest.mark.parametrize(
    "s_before, s_now, s_after, label",
    [
        (0.0, 30.0, 80.0, NORMAL),  # 10 m/s then 10 m/s
        (0.0, 30.0, 69.0, BRAKING),
        (0.0, 30.0, 71.0, NORMAL),
        (5.0, 5.0, 5.0, NORMAL),  # standing still is not braking
    ],
)
def test_longitudinal_label_rule(s_before, s_now, s_after, label):
    got = jax.jit(longitudinal_label)(jnp.float32(s_before), jnp.float32(s_now), jnp.float32(s_after))
    assert int(got) == label



# --- samples read back for training ------------------------------------------------------------

FT = 0.3048  # [m]


def _shard(s: int, nbr_sample: list[int], slots: list[int], sims: list[int], offset: float) -> dict:
    m = len(nbr_sample)
    hist = offset + np.arange(s * 16 * 2, dtype=np.float32).reshape(s, 16, 2) / 8
    return {"hist": hist, "fut": offset + np.arange(s * 25 * 2, dtype=np.float32).reshape(s, 25, 2) / 4,
            "nbr_hist": -offset - np.arange(m * 16 * 2, dtype=np.float32).reshape(m, 16, 2) / 16,
            "nbr_sample": np.asarray(nbr_sample, np.int32), "nbr_slot": np.asarray(slots, np.int8),
            "lat_label": np.arange(s, dtype=np.int8) % 3, "lon_label": np.arange(s, dtype=np.int8) % 2,
            "sim_id": np.asarray(sims, np.int32)}


@pytest.fixture
def dataset(tmp_path):
    shards = [_shard(3, [0, 0, 2], [5, 7, 12], [0, 0, 1], 0.0), _shard(2, [0, 0, 0], [1, 2, 3], [2, 3], 100.0)]
    for k, shard in enumerate(shards):
        np.savez(tmp_path / f"shard_{k:05d}.npz", **shard)
    meta = {"layout_version": LAYOUT_VERSION, "shards": [{"file": "shard_00000.npz", "samples": 3},
                                                          {"file": "shard_00001.npz", "samples": 2}]}
    (tmp_path / "meta.json").write_text(json.dumps(meta))
    return tmp_path, shards


def _model(xy_m: np.ndarray) -> np.ndarray:
    """(lon_m, lat_m left) -> (lateral ft right, longitudinal ft)."""
    return np.stack([-xy_m[..., 1] / FT, xy_m[..., 0] / FT], axis=-1)


def test_neighbours_are_packed_per_sample_in_order(dataset):
    folder, (a, b) = dataset
    samples, meta = load_samples(folder)
    assert len(samples) == 5 and meta["layout_version"] == LAYOUT_VERSION
    np.testing.assert_array_equal(samples.nbr_slot, [[5, 7, -1], [-1, -1, -1], [12, -1, -1], [1, 2, 3], [-1, -1, -1]])
    np.testing.assert_array_equal(samples.nbr_weight, (samples.nbr_slot >= 0).astype(np.float32))
    assert samples.nbr_slot.dtype == np.int32 and samples.nbr_weight.dtype == np.float32
    expected = np.zeros((5, 3, 16, 2), np.float32)
    expected[0, 0], expected[0, 1], expected[2, 0] = (_model(h) for h in a["nbr_hist"])
    expected[3, :3] = _model(b["nbr_hist"])
    np.testing.assert_allclose(samples.nbr_hist, expected, rtol=1e-6)


def test_the_model_frame_is_feet_with_the_lateral_axis_to_the_right(dataset):
    folder, (a, b) = dataset
    samples, _ = load_samples(folder)
    hist_m = np.concatenate([a["hist"], b["hist"]])
    np.testing.assert_array_equal(samples.hist_m, hist_m)
    np.testing.assert_array_equal(samples.fut_m, np.concatenate([a["fut"], b["fut"]]))
    np.testing.assert_allclose(samples.hist, _model(hist_m), rtol=1e-6)
    np.testing.assert_allclose(samples.fut, _model(samples.fut_m), rtol=1e-6)
    assert samples.hist.dtype == samples.fut.dtype == samples.hist_m.dtype == samples.fut_m.dtype == np.float32
    np.testing.assert_array_equal(samples.lat, [0, 1, 2, 0, 1])
    np.testing.assert_array_equal(samples.lon, [0, 1, 0, 0, 1])
    np.testing.assert_array_equal(samples.sim_id, [0, 0, 1, 2, 3])
    assert samples.lat.dtype == samples.lon.dtype == np.int32 and samples.sim_id.dtype == np.int64


@pytest.mark.parametrize(("max_samples", "rows", "width"), [(2, 2, 2), (3, 3, 2), (4, 4, 3), (0, 5, 3), (9, 5, 3)])
def test_max_samples_reads_only_the_shards_it_needs(dataset, max_samples, rows, width):
    folder, _ = dataset
    samples, _ = load_samples(folder, max_samples=max_samples)
    assert len(samples) == rows and samples.nbr_slot.shape == (rows, width)
    assert all(len(getattr(samples, name)) == rows for name in ("fut", "nbr_hist", "lat", "lon", "sim_id", "fut_m"))


def test_reading_stops_once_max_samples_are_read(tmp_path):
    """Shards of 3, 0, 2 and 2 samples; the last one's first sample has 4 neighbours."""
    shards = [_shard(3, [0], [1], [0, 0, 0], 0.0), _shard(0, [], [], [], 0.0), _shard(2, [1, 1], [2, 3], [1, 1], 0.0),
              _shard(2, [0, 0, 0, 0], [4, 5, 6, 7], [2, 2], 0.0)]
    for k, shard in enumerate(shards):
        np.savez(tmp_path / f"{k}.npz", **shard)
    meta = {"layout_version": LAYOUT_VERSION, "shards": [{"file": f"{k}.npz"} for k in range(4)]}
    (tmp_path / "meta.json").write_text(json.dumps(meta))
    assert load_samples(tmp_path, max_samples=4)[0].nbr_slot.shape == (4, 2)  # the last shard unread
    assert load_samples(tmp_path, max_samples=6)[0].nbr_slot.shape == (6, 4)
    np.testing.assert_array_equal(load_samples(tmp_path)[0].nbr_slot[3:5], [[-1, -1, -1, -1], [2, 3, -1, -1]])


def test_a_dataset_without_neighbours_has_one_padding_column(tmp_path):
    np.savez(tmp_path / "s.npz", **_shard(2, [], [], [0, 1], 0.0))
    (tmp_path / "meta.json").write_text(json.dumps({"layout_version": LAYOUT_VERSION, "shards": [{"file": "s.npz"}]}))
    samples, _ = load_samples(tmp_path)
    np.testing.assert_array_equal(samples.nbr_slot, [[-1], [-1]])
    assert samples.nbr_hist.shape == (2, 1, 16, 2) and not samples.nbr_weight.any()


def test_a_dataset_without_samples_or_with_a_malformed_shard_entry_is_refused(tmp_path):
    for shards, culprit in (([], "no samples"), (None, "no samples"), (["s.npz"], "'s.npz'"),
                            ([{"file": 3}], "{'file': 3}")):
        meta = {"layout_version": LAYOUT_VERSION} | ({} if shards is None else {"shards": shards})
        (tmp_path / "meta.json").write_text(json.dumps(meta))
        with pytest.raises(InputError, match=re.escape(culprit)):
            load_samples(tmp_path)


def test_the_split_keeps_simulations_whole(dataset):
    folder, _ = dataset
    samples, _ = load_samples(folder)
    for fraction, n_val in ((0.01, 1), (0.3, 1), (0.5, 2), (0.9, 3), (0.99, 3)):  # of 4 simulations, 1..3
        train, val = split_by_simulation(samples, fraction, seed=1)
        assert len(np.unique(val.sim_id)) == n_val, fraction
        assert not set(train.sim_id) & set(val.sim_id) and len(train) + len(val) == 5
        assert sorted([*train.sim_id, *val.sim_id]) == [0, 0, 1, 2, 3]
    again = split_by_simulation(samples, 0.5, seed=1)[1].sim_id
    np.testing.assert_array_equal(again, split_by_simulation(samples, 0.5, seed=1)[1].sim_id)
    val_sims = np.sort(np.random.default_rng(1).permutation([0, 1, 2, 3])[:2])
    np.testing.assert_array_equal(np.unique(again), val_sims)  # a seeded permutation of the simulations
    two = samples.take(np.flatnonzero(samples.sim_id <= 1))
    assert len(np.unique(split_by_simulation(two, 0.5, seed=0)[1].sim_id)) == 1  # two simulations suffice
    one = samples.take(np.flatnonzero(samples.sim_id == 0))
    with pytest.raises(InputError, match="2 simulations"):
        split_by_simulation(one, 0.5, seed=0)
