"""Training samples read from a dataset written by hand: neighbours packed per sample in their
order (padding slot -1, weight 0), the model frame in feet with the lateral axis to the right,
SI kept beside it, `max_samples` across shards, the labels and simulations, and the split by
whole simulations; refusals by whole message."""

from __future__ import annotations

import json

import numpy as np
import pytest

from diffsense.runtime._errors import InputError
from diffsense.train import load_samples
from diffsense.train._data import split_by_simulation
from diffsense.train._samples import LAYOUT_VERSION

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


def test_refusals_by_whole_message(tmp_path):
    (tmp_path / "meta.json").write_text(json.dumps({"layout_version": LAYOUT_VERSION, "shards": []}))
    with pytest.raises(InputError) as err:
        load_samples(tmp_path)
    assert str(err.value) == f"{tmp_path}: the dataset holds no samples"
    (tmp_path / "meta.json").write_text(json.dumps({"layout_version": LAYOUT_VERSION}))
    with pytest.raises(InputError) as err:
        load_samples(tmp_path)
    assert str(err.value) == f"{tmp_path}: the dataset holds no samples"
    (tmp_path / "meta.json").write_text(json.dumps({"layout_version": LAYOUT_VERSION, "shards": ["s.npz"]}))
    with pytest.raises(InputError) as err:
        load_samples(tmp_path)
    assert str(err.value) == f"{tmp_path}/meta.json: malformed shard entry 's.npz'"
    (tmp_path / "meta.json").write_text(json.dumps({"layout_version": LAYOUT_VERSION, "shards": [{"file": 3}]}))
    with pytest.raises(InputError) as err:
        load_samples(tmp_path)
    assert str(err.value) == f"{tmp_path}/meta.json: malformed shard entry {{'file': 3}}"


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
    with pytest.raises(InputError) as err:
        split_by_simulation(one, 0.5, seed=0)
    assert str(err.value) == "the dataset must hold at least 2 simulations to hold some out for validation"
