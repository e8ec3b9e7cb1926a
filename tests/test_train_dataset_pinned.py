"""Datasets written and read: simulation n's samples come from the key fold_in(key(seed), n)
whatever the batching, a truncated last simulation, neighbour rows re-pointed across shards,
meta.json's counts and names, the folder published whole or not at all, and every refusal of a
malformed meta.json or shard by its whole message. Expected values are worked out by hand or
from one simulation at a time, never from the batching under test."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import jax
import numpy as np
import pytest

from diffsense.runtime import _io
from diffsense.config import to_dict
from diffsense.runtime._errors import InputError
from diffsense.train._dataset import (
    _simulate_batch, _traced_part, concatenate_shards, extract_batch, generate_samples, read_dataset,
    read_meta, read_shard, samples_per_simulation, simulate_batch, simulation_keys, write_dataset,
)
from diffsense.train._samples import compact_samples
from test_traffic import small_config

CFG1 = small_config(simulations_per_shard=1)  # one simulation per batch: one compiled shape
PER_SIM = 15 * 11  # 3 lanes x 5 vehicles, instants at 0, 2, ..., 20 s of the window


def test_samples_per_simulation_are_vehicles_times_instants():
    assert samples_per_simulation(CFG1) == PER_SIM
    cfg = small_config(window_s=7.2, instant_every_s=0.6)
    assert samples_per_simulation(cfg) == 15 * 13


def test_simulation_keys_fold_each_index_into_the_root_key():
    key = jax.random.key(3)
    got = jax.random.key_data(simulation_keys(key, 5, 3))
    want = np.stack([jax.random.key_data(jax.random.fold_in(key, n)) for n in (5, 6, 7)])
    np.testing.assert_array_equal(got, want)


def test_the_compiled_simulation_ignores_count_seed_and_batch_size():
    other = dataclasses.replace(CFG1, sampling=dataclasses.replace(
        CFG1.sampling, num_samples=77, seed=9, simulations_per_shard=3))
    assert _traced_part(other) == _traced_part(CFG1) and other != CFG1
    longer = small_config(simulations_per_shard=1, warmup_s=11.0)
    assert _traced_part(longer) != _traced_part(CFG1)


def _one_at_a_time(key, n: int, keep: int) -> dict[str, np.ndarray]:
    """Simulation n alone, its first `keep` samples in the shard layout."""
    keys = jax.random.fold_in(key, n)[None]
    dense = extract_batch(CFG1, simulate_batch(CFG1, keys))
    dense = jax.tree_util.tree_map(lambda a: np.asarray(a)[:keep], dense)
    return compact_samples(dense, np.full(keep, n))


@pytest.fixture(scope="module")
def alone():
    key = jax.random.key(5)
    return [_one_at_a_time(key, n, keep) for n, keep in ((0, PER_SIM), (1, PER_SIM), (2, 3))]


def _concatenated(parts: list[dict]) -> dict[str, np.ndarray]:
    """By hand: simulation n's neighbour rows point n * PER_SIM rows further."""
    out = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    out["nbr_sample"] = np.concatenate([p["nbr_sample"] + n * PER_SIM for n, p in enumerate(parts)])
    return out


def test_generated_samples_are_each_simulation_alone_the_last_truncated(alone):
    got = generate_samples(CFG1, 2 * PER_SIM + 3, jax.random.key(5))
    want = _concatenated(alone)
    assert sorted(got) == sorted(want)
    for k in want:
        np.testing.assert_array_equal(got[k], want[k], err_msg=k)
    assert got["sim_id"].tolist() == [0] * PER_SIM + [1] * PER_SIM + [2] * 3
    assert got["nbr_sample"].dtype == np.int32 and len(got["hist"]) == 2 * PER_SIM + 3
    assert len(alone[2]["nbr_slot"]) > 0  # the truncated simulation still has neighbours
    with pytest.raises(InputError, match=r"^num_samples must be >= 1, got 0$"):
        generate_samples(CFG1, 0, jax.random.key(5))


def test_changing_the_seed_or_count_reuses_the_compiled_simulation(alone):
    generate_samples(CFG1, 1, jax.random.key(5))  # compiled here: caches may be cleared between tests
    before = _simulate_batch._cache_size()
    other = dataclasses.replace(CFG1, sampling=dataclasses.replace(CFG1.sampling, seed=9, num_samples=2))
    got = generate_samples(other, 2, jax.random.key(5))
    assert _simulate_batch._cache_size() == before
    np.testing.assert_array_equal(got["hist"], alone[0]["hist"][:2])


def test_a_dataset_holds_one_shard_per_batch_and_counts_what_it_holds(tmp_path, alone):
    sizes, beside, registered = [], [], []
    out = tmp_path / "deep" / "er" / "set"

    def progress(n):  # while a shard is written: the temporary folder beside `out`, registered
        sizes.append(n)
        beside.append(sorted(p.name for p in out.parent.iterdir()))
        registered.append(sorted(p for p in _io._TEMPORARIES if Path(p).parent == out.parent))

    meta = write_dataset(CFG1, out, 2 * PER_SIM + 3, 5, progress=progress)
    assert sizes == [PER_SIM, PER_SIM, 3]
    (partial,) = beside[0]
    assert partial.startswith(".set.") and partial.endswith(".partial") and beside == [[partial]] * 3
    assert registered == [[str(out.parent / partial)]] * 3
    assert not [p for p in _io._TEMPORARIES if Path(p).parent == out.parent]  # released once published
    shards = list(read_dataset(out))
    for got, want in zip(shards, alone, strict=True):
        for k in want:
            np.testing.assert_array_equal(got[k], want[k], err_msg=k)
    assert json.loads((out / "meta.json").read_text()) == meta == read_meta(out)
    labels_lat = np.concatenate([s["lat_label"] for s in alone])
    labels_lon = np.concatenate([s["lon_label"] for s in alone])
    assert meta["lat_label_counts"] == {k: int((labels_lat == v).sum()) for k, v in (("keep", 0), ("left", 1), ("right", 2))}
    assert meta["lon_label_counts"] == {"normal": int((labels_lon == 0).sum()), "braking": int((labels_lon == 1).sum())}
    assert meta["shards"] == [
        {"file": f"shard_0000{i}.npz", "num_samples": len(s["hist"]), "num_neighbours": len(s["nbr_slot"])}
        for i, s in enumerate(alone)]
    assert meta["num_neighbours"] == sum(len(s["nbr_slot"]) for s in alone)
    assert {k: meta[k] for k in ("layout_version", "seed", "num_samples", "num_simulations", "samples_per_simulation",
                                 "rate_hz", "hist_len", "fut_len", "grid")} == {
        "layout_version": 1, "seed": 5, "num_samples": 2 * PER_SIM + 3, "num_simulations": 3,
        "samples_per_simulation": PER_SIM, "rate_hz": 5.0, "hist_len": 16, "fut_len": 25,
        "grid": {"lanes": 3, "cells": 13, "cell_m": 15 * 0.3048, "slots": 39}}
    assert meta["config"] == to_dict(CFG1)
    assert meta["frame"] == "SI road frame of the target at the prediction instant: (lon_m forward, lat_m left)"
    assert sorted(p.name for p in out.iterdir()) == ["meta.json", "shard_00000.npz", "shard_00001.npz", "shard_00002.npz"]
    assert [p.name for p in out.parent.iterdir()] == ["set"]  # no temporary left beside it


def test_an_empty_folder_is_filled_and_anything_else_refused(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    assert write_dataset(CFG1, empty, 2, 5)["num_samples"] == 2
    assert write_dataset(CFG1, tmp_path / "one", 1, 5)["num_samples"] == 1  # the least there is
    for name, make in (("full", lambda p: (p.mkdir(), (p / "x").write_text(""))), ("file", lambda p: p.write_text(""))):
        make(tmp_path / name)
        with pytest.raises(InputError) as e:
            write_dataset(CFG1, tmp_path / name, 2, 5)
        assert str(e.value) == f"output {tmp_path / name} already exists and is not an empty folder"
    with pytest.raises(InputError) as e:
        write_dataset(CFG1, tmp_path / "new" / "set", 0, 5)
    assert str(e.value) == "number of samples must be >= 1, got 0"
    assert not (tmp_path / "new").exists()


@pytest.mark.parametrize("during", ["interrupt", "folder appears"])
def test_a_failed_write_leaves_nothing_of_its_own(tmp_path, during):
    out = tmp_path / "set"

    def progress(n):
        if during == "interrupt":
            raise KeyboardInterrupt
        out.mkdir(exist_ok=True)
        (out / "theirs").write_text("kept")

    with pytest.raises(KeyboardInterrupt if during == "interrupt" else InputError):
        write_dataset(CFG1, out, 2, 5, progress=progress)
    assert [p.name for p in tmp_path.iterdir()] == ([] if during == "interrupt" else ["set"])
    if during != "interrupt":
        assert [p.name for p in out.iterdir()] == ["theirs"]


def _shard(s: int, nbr_sample: list[int], slots: list[int], offset: float = 0.0) -> dict[str, np.ndarray]:
    m = len(nbr_sample)
    return {"hist": np.full((s, 16, 2), offset, np.float32), "fut": np.full((s, 25, 2), offset, np.float32),
            "nbr_hist": np.full((m, 16, 2), -offset, np.float32), "nbr_sample": np.asarray(nbr_sample, np.int32),
            "nbr_slot": np.asarray(slots, np.int8), "lat_label": np.arange(s, dtype=np.int8) % 3,
            "lon_label": np.arange(s, dtype=np.int8) % 2, "sim_id": np.full(s, int(offset), np.int32)}


def test_concatenated_shards_point_their_neighbours_at_their_own_samples():
    parts = [_shard(2, [0, 1, 1], [3, 4, 5], 0.0), _shard(3, [], [], 1.0), _shard(1, [0, 0], [7, 8], 2.0)]
    got = concatenate_shards(parts)
    assert got["nbr_sample"].tolist() == [0, 1, 1, 5, 5] and got["nbr_sample"].dtype == np.int32
    assert got["nbr_slot"].tolist() == [3, 4, 5, 7, 8] and got["sim_id"].tolist() == [0, 0, 1, 1, 1, 2]
    assert got["hist"][:, 0, 0].tolist() == [0, 0, 1, 1, 1, 2] and got["nbr_hist"][:, 0, 0].tolist() == [0, 0, 0, -2, -2]
    assert sorted(got) == sorted(parts[0])


def test_shards_are_read_in_the_order_meta_lists_them(tmp_path):
    for name, offset in (("b.npz", 1.0), ("a.npz", 2.0)):
        np.savez(tmp_path / name, **_shard(1, [], [], offset))
    (tmp_path / "meta.json").write_text(json.dumps({"layout_version": 1, "shards": [{"file": "b.npz"}, {"file": "a.npz"}]}))
    assert [float(s["hist"][0, 0, 0]) for s in read_dataset(tmp_path)] == [1.0, 2.0]


def test_meta_refusals_by_whole_message(tmp_path):
    meta = tmp_path / "meta.json"
    with pytest.raises(InputError) as e:
        read_meta(tmp_path)
    assert str(e.value) == f"{tmp_path} is not a traffic dataset: no meta.json"
    for text, version in (("[1]", "None"), ('{"layout_version": 2}', "2"), ("{}", "None")):
        meta.write_text(text)
        with pytest.raises(InputError) as e:
            read_meta(tmp_path)
        assert str(e.value) == f"{meta}: layout version {version}, expected 1"
    meta.write_text("{")
    with pytest.raises(InputError, match=r"^cannot read .*meta\.json: Expecting property name"):
        read_meta(tmp_path)


def _refusal(tmp_path, **change) -> str:
    shard = dict(_shard(3, [0, 2, 2], [0, 38, 1]), **change)
    file = tmp_path / "s.npz"
    np.savez(file, **{k: v for k, v in shard.items() if v is not None})
    with pytest.raises(InputError) as e:
        read_shard(file)
    return str(e.value).replace(str(file), "F")


def test_a_shard_at_every_limit_is_read(tmp_path):
    np.savez(tmp_path / "s.npz", **_shard(3, [0, 2, 2], [0, 38, 1]))
    shard = read_shard(tmp_path / "s.npz")
    assert shard["lat_label"].tolist() == [0, 1, 2] and shard["lon_label"].tolist() == [0, 1, 0]
    np.savez(tmp_path / "none.npz", **_shard(0, [], []))
    assert len(read_shard(tmp_path / "none.npz")["hist"]) == 0


@pytest.mark.parametrize("change, message", [
    ({"fut": None}, "shard F lacks array 'fut'"),
    ({"hist": np.zeros((3, 16, 2))}, "shard F: hist is float64 (3, 16, 2), expected float32 (3, 16, 2)"),
    ({"fut": np.zeros((3, 24, 2), np.float32)}, "shard F: fut is float32 (3, 24, 2), expected float32 (3, 25, 2)"),
    ({"nbr_hist": np.zeros((3, 15, 2), np.float32)}, "shard F: nbr_hist is float32 (3, 15, 2), expected float32 (3, 16, 2)"),
    ({"nbr_sample": np.array([0, 2], np.int32)}, "shard F: nbr_sample is int32 (2,), expected int32 (3,)"),
    ({"nbr_slot": np.array([0, 38, 1], np.int16)}, "shard F: nbr_slot is int16 (3,), expected int8 (3,)"),
    ({"lat_label": np.zeros(2, np.int8)}, "shard F: lat_label is int8 (2,), expected int8 (3,)"),
    ({"lon_label": np.zeros(3, np.int32)}, "shard F: lon_label is int32 (3,), expected int8 (3,)"),
    ({"sim_id": np.zeros(3, np.int64)}, "shard F: sim_id is int64 (3,), expected int32 (3,)"),
    ({"fut": np.full((3, 25, 2), np.inf, np.float32)}, "shard F: fut holds NaN or inf"),
    ({"nbr_hist": np.full((3, 16, 2), np.nan, np.float32)}, "shard F: nbr_hist holds NaN or inf"),
    ({"nbr_sample": np.array([-1, 0, 0], np.int32)}, "shard F: nbr_sample must be non-decreasing rows 0..2"),
    ({"nbr_sample": np.array([0, 1, 3], np.int32)}, "shard F: nbr_sample must be non-decreasing rows 0..2"),
    ({"nbr_sample": np.array([0, 2, 1], np.int32)}, "shard F: nbr_sample must be non-decreasing rows 0..2"),
    ({"nbr_slot": np.array([-1, 0, 1], np.int8)}, "shard F: nbr_slot must be grid ids 0..38"),
    ({"nbr_slot": np.array([0, 39, 1], np.int8)}, "shard F: nbr_slot must be grid ids 0..38"),
    ({"lat_label": np.array([0, 3, 1], np.int8)}, "shard F: labels out of range (lat 0..2, lon 0..1)"),
    ({"lat_label": np.array([0, -1, 1], np.int8)}, "shard F: labels out of range (lat 0..2, lon 0..1)"),
    ({"lon_label": np.array([0, 2, 1], np.int8)}, "shard F: labels out of range (lat 0..2, lon 0..1)"),
    ({"lon_label": np.array([0, -1, 1], np.int8)}, "shard F: labels out of range (lat 0..2, lon 0..1)"),
])
def test_shard_refusals_by_whole_message(tmp_path, change, message):
    assert _refusal(tmp_path, **change) == message


def test_unreadable_shards_by_whole_message(tmp_path):
    with pytest.raises(InputError) as e:
        read_shard(tmp_path / "gone.npz")
    assert str(e.value) == f"missing shard {tmp_path / 'gone.npz'}"
    (tmp_path / "junk.npz").write_bytes(b"PK\x03\x04 not a zip")
    with pytest.raises(InputError, match=r"^cannot read shard .*junk\.npz: "):
        read_shard(tmp_path / "junk.npz")
