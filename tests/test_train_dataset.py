"""Datasets generated, written and read: simulation n's samples come from the key
fold_in(key(seed), n) whatever the batching, bit for bit for a seed, a truncated last simulation,
neighbour rows re-pointed across shards, meta.json's counts, the folder published whole or not at
all, every malformed meta.json or shard refused naming the file and the culprit, and the
`generate` command. Expected values are worked out by hand or from one simulation at a time,
never from the batching under test."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys

import jax
import numpy as np
import pytest

from diffsense.cli import run
from diffsense.cli.generate import main
from diffsense.config import to_dict
from diffsense.predictors import CSLSTM_SPEC
from diffsense.runtime import InputError
from diffsense.scene import TrafficConfig
from diffsense.train import (
    concatenate_shards,
    extract_batch,
    generate_samples,
    read_dataset,
    read_meta,
    read_shard,
    samples_per_simulation,
    shard_arrays,
    simulate_batch,
    write_dataset,
)


def small_config(**sampling) -> TrafficConfig:
    """Dense, short, small: 3 lanes x 5 vehicles, 29 s recorded."""
    base = TrafficConfig()
    sampling = {"warmup_s": 10.0, "window_s": 20.0, "instant_every_s": 2.0, "simulations_per_shard": 4} | sampling
    return dataclasses.replace(
        base, road=dataclasses.replace(base.road, num_lanes=3, vehicles_per_lane=5),
        traffic=dataclasses.replace(base.traffic, density_veh_per_km_lane=(25.0, 70.0)),
        sampling=dataclasses.replace(base.sampling, **sampling))


CFG = small_config()  # four simulations per batch
CFG1 = small_config(simulations_per_shard=1)  # one simulation per batch: one compiled shape
LANE_W = 3.66  # the default road's lane width [m]
PER_SIM = 15 * 11  # 3 lanes x 5 vehicles, instants at 0, 2, ..., 20 s of the window


def test_samples_per_simulation_are_vehicles_times_instants():
    assert samples_per_simulation(CFG1) == PER_SIM
    cfg = small_config(window_s=7.2, instant_every_s=0.6)
    assert samples_per_simulation(cfg) == 15 * 13


def _one_at_a_time(key, n: int, keep: int) -> dict[str, np.ndarray]:
    """Simulation n alone, its first `keep` samples in the shard layout."""
    keys = jax.random.fold_in(key, n)[None]  # what simulation_keys(key, n, 1) must give
    return shard_arrays(CFG1, n, keep, extract_batch(CFG1, simulate_batch(CFG1, keys)))


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
    with pytest.raises(InputError, match="num_samples"):
        generate_samples(CFG1, 0, jax.random.key(5))


def test_a_dataset_holds_one_shard_per_batch_and_counts_what_it_holds(tmp_path, alone):
    sizes, beside = [], []
    out = tmp_path / "deep" / "er" / "set"

    def progress(n):  # while a shard is written: `out` not there yet, one temporary beside it
        sizes.append(n)
        beside.append(sorted(p.name for p in out.parent.iterdir()))

    meta = write_dataset(CFG1, out, 2 * PER_SIM + 3, 5, progress=progress)
    assert sizes == [PER_SIM, PER_SIM, 3]
    assert len(beside[0]) == 1 and "set" not in beside[0] and beside == [beside[0]] * 3
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
    assert sorted(p.name for p in out.iterdir()) == ["meta.json", "shard_00000.npz", "shard_00001.npz", "shard_00002.npz"]
    assert [p.name for p in out.parent.iterdir()] == ["set"]  # no temporary left beside it


def test_an_empty_folder_is_filled_and_anything_else_refused(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    assert write_dataset(CFG1, empty, 2, 5)["num_samples"] == 2
    assert write_dataset(CFG1, tmp_path / "one", 1, 5)["num_samples"] == 1  # the least there is
    for name, make in (("full", lambda p: (p.mkdir(), (p / "x").write_text(""))), ("file", lambda p: p.write_text(""))):
        make(tmp_path / name)
        with pytest.raises(InputError, match=str(tmp_path / name)):
            write_dataset(CFG1, tmp_path / name, 2, 5)
    with pytest.raises(InputError, match="samples"):
        write_dataset(CFG1, tmp_path / "new" / "set", 0, 5)
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


def test_meta_refusals_name_the_file(tmp_path):
    meta = tmp_path / "meta.json"
    with pytest.raises(InputError, match="meta.json"):
        read_meta(tmp_path)
    for text, version in (("[1]", "None"), ('{"layout_version": 2}', "2"), ("{}", "None")):
        meta.write_text(text)
        with pytest.raises(InputError, match=f"{meta}: layout version {version}"):
            read_meta(tmp_path)
    meta.write_text("{")
    with pytest.raises(InputError, match=str(meta)):
        read_meta(tmp_path)


def _refusal(tmp_path, **change) -> str:
    shard = dict(_shard(3, [0, 2, 2], [0, 38, 1]), **change)
    file = tmp_path / "s.npz"
    np.savez(file, **{k: v for k, v in shard.items() if v is not None})
    with pytest.raises(InputError) as e:
        read_shard(file)
    assert str(file) in str(e.value)
    return str(e.value).replace(str(file), "F")


def test_a_shard_at_every_limit_is_read(tmp_path):
    np.savez(tmp_path / "s.npz", **_shard(3, [0, 2, 2], [0, 38, 1]))
    shard = read_shard(tmp_path / "s.npz")
    assert shard["lat_label"].tolist() == [0, 1, 2] and shard["lon_label"].tolist() == [0, 1, 0]
    np.savez(tmp_path / "none.npz", **_shard(0, [], []))
    assert len(read_shard(tmp_path / "none.npz")["hist"]) == 0


_F32, _I8, _I32 = np.float32, np.int8, np.int32
_BROKEN = {  # array -> values breaking the layout: dtype, shape, finiteness, index ranges
    "fut": [None, np.zeros((3, 24, 2), _F32), np.full((3, 25, 2), np.inf, _F32)], "hist": [np.zeros((3, 16, 2))],
    "nbr_hist": [np.zeros((3, 15, 2), _F32), np.full((3, 16, 2), np.nan, _F32)],
    "nbr_sample": [np.array(v, _I32) for v in ([0, 2], [-1, 0, 0], [0, 1, 3], [0, 2, 1])],
    "nbr_slot": [np.array([0, 38, 1], np.int16), np.array([-1, 0, 1], _I8), np.array([0, 39, 1], _I8)],
    "lat_label": [np.zeros(2, _I8), np.array([0, 3, 1], _I8), np.array([0, -1, 1], _I8)],
    "lon_label": [np.zeros(3, _I32), np.array([0, 2, 1], _I8), np.array([0, -1, 1], _I8)], "sim_id": [np.zeros(3, np.int64)],
}


@pytest.mark.parametrize("name, value", [(k, v) for k, vs in _BROKEN.items() for v in vs])
def test_a_shard_breaking_the_layout_is_refused_naming_the_array(tmp_path, name, value):
    assert name.removesuffix("_label") in _refusal(tmp_path, **{name: value})


def test_unreadable_shards_are_refused_naming_the_file(tmp_path):
    for name, data in (("gone.npz", None), ("junk.npz", b"PK\x03\x04 not a zip")):
        if data is not None:
            (tmp_path / name).write_bytes(data)
        with pytest.raises(InputError, match=str(tmp_path / name)):
            read_shard(tmp_path / name)


NUM = 3 * samples_per_simulation(CFG) + 50  # four simulations (one batch), the last one truncated


@pytest.fixture(scope="module")
def dataset():
    return generate_samples(CFG, NUM, jax.random.key(11))


def test_dataset_layout(dataset):
    s, m = len(dataset["hist"]), len(dataset["nbr_hist"])
    assert s == NUM and m > s
    assert dataset["hist"].dtype == np.float32 and dataset["hist"].shape == (s, 16, 2)
    assert dataset["fut"].shape == (s, 25, 2) and dataset["nbr_hist"].shape == (m, 16, 2)
    assert dataset["nbr_sample"].dtype == np.int32 and dataset["nbr_slot"].dtype == np.int8
    assert dataset["lat_label"].dtype == np.int8 and dataset["lon_label"].dtype == np.int8
    assert (np.diff(dataset["nbr_sample"]) >= 0).all() and dataset["nbr_sample"].max() < s
    assert 0 <= dataset["nbr_slot"].min() and dataset["nbr_slot"].max() < 39
    assert dataset["sim_id"].tolist() == sorted(dataset["sim_id"].tolist()) and dataset["sim_id"].max() == 3
    assert np.isfinite(dataset["nbr_hist"]).all() and (dataset["hist"][:, -1] == 0).all()
    # Each neighbour's last history point is within the grid of its sample's target.
    lon_now, lat_now = dataset["nbr_hist"][:, -1, 0], dataset["nbr_hist"][:, -1, 1]
    cell = dataset["nbr_slot"] % 13
    lane = dataset["nbr_slot"] // 13
    np.testing.assert_array_equal(np.round(lon_now / CSLSTM_SPEC.grid_cell_m) + 6, cell)
    assert (np.sign(np.round(lat_now / LANE_W)) == 1 - lane).all()
    # No (sample, slot) twice.
    pairs = dataset["nbr_sample"].astype(np.int64) * 39 + dataset["nbr_slot"]
    assert len(np.unique(pairs)) == m


def test_samples_are_the_seeds_bit_for_bit_whatever_the_batching(dataset):
    # Batches of two over four simulations: the tests above batch one at a time, where a batch
    # launched at every simulation instead of every second one cannot show.
    for got in (generate_samples(CFG, NUM, jax.random.key(11)), generate_samples(small_config(simulations_per_shard=2),
                                                                              NUM, jax.random.key(11))):
        for k in dataset:
            np.testing.assert_array_equal(dataset[k], got[k], err_msg=k)
    assert not np.array_equal(generate_samples(CFG, NUM, jax.random.key(12))["hist"], dataset["hist"])


def _toml(table: dict, prefix: str = "") -> str:
    """Enough of a TOML writer for a config dict (numbers, strings, lists, nested tables)."""
    lines, subs = [], []
    for k, v in table.items():
        if isinstance(v, dict):
            subs.append(f"\n[{prefix}{k}]\n" + _toml(v, f"{prefix}{k}."))
        else:
            lines.append(f"{k} = {v!r}".replace("(", "[").replace(")", "]").replace("'", '"'))
    return "\n".join(lines) + "".join(subs) + "\n"


def test_cli_writes_a_readable_dataset(tmp_path, monkeypatch, dataset, capsys):
    monkeypatch.setenv("DIFFSENSE_NO_CACHE", "1")
    config = tmp_path / "traffic.toml"
    config.write_text(_toml(to_dict(CFG)))
    out = tmp_path / "set"
    assert main(["--config", str(config), "--out", str(out), "--samples", str(NUM), "--seed", "11", "--no-progress"]) == 0
    assert f"wrote {NUM} samples" in capsys.readouterr().out
    meta = read_meta(out)
    assert meta["num_samples"] == NUM and meta["seed"] == 11 and meta["config"] == to_dict(small_config(num_samples=NUM, seed=11))
    assert sum(meta["lat_label_counts"].values()) == NUM
    shards = list(read_dataset(out))
    assert len(shards) == len(meta["shards"]) == 1  # four simulations, one shard
    for k in dataset:
        np.testing.assert_array_equal(shards[0][k], dataset[k], err_msg=k)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["set", "traffic.toml"]  # no temporary left
    with pytest.raises(SystemExit) as e:  # never overwrites a dataset
        run(lambda: main(["--config", str(config), "--out", str(out), "--samples", "10"]))
    assert e.value.code == 2 and "already exists" in capsys.readouterr().err


@pytest.mark.slow
def test_cli_process_without_x64_writes_the_same_samples(tmp_path, dataset):
    # The tests run with jax_enable_x64; `python -m diffsense.scene generate` without: same bits.
    config = tmp_path / "traffic.toml"
    config.write_text(_toml(to_dict(CFG)))
    out = tmp_path / "set"
    proc = subprocess.run(
        [sys.executable, "-m", "diffsense.scene", "generate", "--config", str(config), "--out", str(out),
         "--samples", str(NUM), "--seed", "11", "--no-progress"],
        capture_output=True, text=True, timeout=600, env=dict(os.environ, DIFFSENSE_NO_CACHE="1"),
    )
    assert proc.returncode == 0, proc.stderr
    (shard,) = read_dataset(out)
    for k in dataset:
        np.testing.assert_array_equal(shard[k], dataset[k], err_msg=k)


@pytest.mark.parametrize("text, culprit", [
    ("[road]\nnum_lanes = 3\nlanes_wide = 2\n", "road.lanes_wide"),
    ("[traffic]\ndensity_veh_per_km_lane = [60.0, 10.0]\n", "density_veh_per_km_lane"),
    ("[sampling]\nwarmup_s = 'long'\n", "sampling.warmup_s"),
    ("[road\n", "bad.toml"),
])
def test_cli_rejects_a_bad_config_with_one_line_and_exit_2(tmp_path, capsys, text, culprit):
    config = tmp_path / "bad.toml"
    config.write_text(text)
    with pytest.raises(SystemExit) as e:
        run(lambda: main(["--config", str(config), "--out", str(tmp_path / "set")]))
    err = capsys.readouterr().err
    assert e.value.code == 2 and err.count("\n") == 1 and err.startswith("error: ") and culprit in err, err
    assert not (tmp_path / "set").exists()


def test_cli_rejects_bad_arguments(tmp_path, capsys):
    for argv, needle in [(["--out", str(tmp_path / "a"), "--samples", "0"], "num_samples"), (["--out"], "--out"), (["--out", str(tmp_path / "b"), "--bogus"], "bogus")]:
        with pytest.raises(SystemExit) as e:
            run(lambda: main(argv))
        err = capsys.readouterr().err
        assert e.value.code == 2 and err.count("\n") == 1 and needle in err, err
