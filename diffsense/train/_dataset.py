"""Training sets from simulated traffic: generate in vectorised batches, write and read shards.

Simulation n of a dataset with seed S uses the key `fold_in(key(S), n)`, so a sample depends only
on (config, seed, simulation index), not on how the work is batched. One batch of
`sampling.simulations_per_shard` simulations is one jitted call (vmap over simulations of the
lax.scan over time, then the sample extraction) and becomes one shard. The layout of the shards
and of meta.json is documented in diffsense.train._samples.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import os
import shutil
import tempfile
import zipfile
from collections.abc import Callable, Iterator
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import PRNGKeyArray

from diffsense.config import to_dict
from diffsense.runtime import (
    InputError,
    atomic_open,
    register_temporary,
    release_temporary,
    write_json,
)
from diffsense.scene import TrafficConfig, TrafficTrajectories, simulate_traffic
from diffsense.train._samples import (
    FUT_LEN,
    GRID_CELL_M,
    GRID_SLOTS,
    HIST_LEN,
    LAYOUT_VERSION,
    DenseSamples,
    compact_samples,
    extract_samples,
    num_instants,
)

META_FILE = "meta.json"
SHARD_KEYS = ("hist", "fut", "nbr_hist", "nbr_sample", "nbr_slot", "lat_label", "lon_label", "sim_id")


def samples_per_simulation(cfg: TrafficConfig) -> int:
    """Samples one simulation yields: vehicles x prediction instants [-]."""
    return cfg.num_vehicles * num_instants(cfg.sampling.window_s, cfg.sampling.instant_every_s)


def simulation_keys(key: PRNGKeyArray, first: int, count: int) -> PRNGKeyArray:
    """Keys of simulations first .. first + count - 1 of a dataset whose root key is `key`."""
    return jax.vmap(lambda n: jax.random.fold_in(key, n))(jnp.arange(first, first + count, dtype=jnp.uint32))


def _traced_part(cfg: TrafficConfig) -> TrafficConfig:
    """`cfg` without the fields that do not enter the computation (sample count, seed, batch size),
    so that changing them reuses the compiled simulation."""
    sampling = dataclasses.replace(cfg.sampling, num_samples=1, seed=0, simulations_per_shard=1)
    return dataclasses.replace(cfg, sampling=sampling)


def simulate_batch(cfg: TrafficConfig, keys: PRNGKeyArray) -> TrafficTrajectories:
    """Independent simulations, one per key: trajectories [N, T, V] (jitted)."""
    return _simulate_batch(_traced_part(cfg), keys)


def extract_batch(cfg: TrafficConfig, traj: TrafficTrajectories) -> DenseSamples:
    """Samples of a batch of simulations, flattened simulation-major: [N * samples_per_simulation] (jitted)."""
    return _extract_batch(_traced_part(cfg), traj)


@functools.partial(jax.jit, static_argnums=0)
def _simulate_batch(cfg: TrafficConfig, keys: PRNGKeyArray) -> TrafficTrajectories:
    return jax.vmap(simulate_traffic, in_axes=(None, 0))(cfg, keys)


@functools.partial(jax.jit, static_argnums=0)
def _extract_batch(cfg: TrafficConfig, traj: TrafficTrajectories) -> DenseSamples:
    sampling = cfg.sampling
    dense = jax.vmap(lambda t: extract_samples(t, cfg.road.lane_width_m, sampling.window_s, sampling.instant_every_s))(traj)
    return jax.tree_util.tree_map(lambda a: a.reshape((-1,) + a.shape[2:]), dense)


def _batches(cfg: TrafficConfig, num_samples: int, key: PRNGKeyArray) -> Iterator[tuple[int, int, DenseSamples]]:
    """(first simulation, samples kept, dense samples) per batch; the next batch is dispatched
    before the current one is handed out, so simulation overlaps the caller's writing."""
    per_sim = samples_per_simulation(cfg)
    num_sims = -(-num_samples // per_sim)
    batch = min(cfg.sampling.simulations_per_shard, num_sims)  # no idle simulations for a small set

    def launch(first):
        return extract_batch(cfg, simulate_batch(cfg, simulation_keys(key, first, batch)))

    firsts = list(range(0, num_sims, batch))
    pending = launch(firsts[0])
    for i, first in enumerate(firsts):
        current = pending
        if i + 1 < len(firsts):
            pending = launch(firsts[i + 1])
        keep = min(batch * per_sim, num_samples - first * per_sim)
        yield first, keep, current


def shard_arrays(cfg: TrafficConfig, first: int, keep: int, dense: DenseSamples) -> dict[str, np.ndarray]:
    """The first `keep` samples of one simulated batch (whose first simulation is number `first`)
    as the compact arrays of one shard file."""
    dense = jax.tree_util.tree_map(lambda a: np.asarray(a)[:keep], dense)
    sim_id = first + np.arange(keep) // samples_per_simulation(cfg)
    return compact_samples(dense, sim_id)


def generate_samples(cfg: TrafficConfig, num_samples: int, key: PRNGKeyArray) -> dict[str, np.ndarray]:
    """`num_samples` training samples in the shard layout (diffsense.train._samples), in memory."""
    if num_samples < 1:
        raise InputError(f"num_samples must be >= 1, got {num_samples}")
    parts = [shard_arrays(cfg, first, keep, dense) for first, keep, dense in _batches(cfg, num_samples, key)]
    return concatenate_shards(parts)


def concatenate_shards(shards: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """One shard from several (neighbour rows re-pointed at the concatenated samples)."""
    offsets = np.cumsum([0] + [len(s["hist"]) for s in shards[:-1]])
    out = {k: np.concatenate([s[k] for s in shards]) for k in SHARD_KEYS if k != "nbr_sample"}
    out["nbr_sample"] = np.concatenate([s["nbr_sample"] + o for s, o in zip(shards, offsets)]).astype(np.int32)
    return out


def check_output_dir(out: Path) -> None:
    """InputError unless `out` is absent or an empty folder (a dataset never overwrites)."""
    if out.exists() and not (out.is_dir() and not any(out.iterdir())):
        raise InputError(f"output {out} already exists and is not an empty folder")


def write_dataset(
    cfg: TrafficConfig,
    out_dir: str | os.PathLike[str],
    num_samples: int,
    seed: int,
    progress: Callable[[int], None] | None = None,
) -> dict:
    """Generate `num_samples` samples with `seed` into the folder `out_dir`; returns meta.json's dict.

    The folder is built under a temporary name next to `out_dir` and renamed when complete, so a
    reader never sees a partial dataset. `progress(n)` is called after each shard with its size.
    """
    out = Path(out_dir)
    check_output_dir(out)
    if num_samples < 1:
        raise InputError(f"number of samples must be >= 1, got {num_samples}")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}.", suffix=".partial"))
    register_temporary(tmp)  # an interrupt removes it (diffsense.cli.run)
    try:
        shards, lat, lon, neighbours = [], np.zeros(3, np.int64), np.zeros(2, np.int64), 0
        for index, (first, keep, dense) in enumerate(_batches(cfg, num_samples, jax.random.key(seed))):
            shard = shard_arrays(cfg, first, keep, dense)
            name = f"shard_{index:05d}.npz"
            with atomic_open(tmp / name) as f:
                np.savez(f, **shard)
            lat += np.bincount(shard["lat_label"], minlength=3)
            lon += np.bincount(shard["lon_label"], minlength=2)
            neighbours += len(shard["nbr_slot"])
            shards.append({"file": name, "num_samples": keep, "num_neighbours": len(shard["nbr_slot"])})
            if progress is not None:
                progress(keep)
        meta = {
            "layout_version": LAYOUT_VERSION,
            "seed": seed,
            "num_samples": num_samples,
            "num_neighbours": neighbours,
            "num_simulations": -(-num_samples // samples_per_simulation(cfg)),
            "samples_per_simulation": samples_per_simulation(cfg),
            "rate_hz": 5.0,
            "hist_len": HIST_LEN,
            "fut_len": FUT_LEN,
            "grid": {"lanes": 3, "cells": 13, "cell_m": GRID_CELL_M, "slots": GRID_SLOTS},
            "frame": "SI road frame of the target at the prediction instant: (lon_m forward, lat_m left)",
            "lat_label_counts": {"keep": int(lat[0]), "left": int(lat[1]), "right": int(lat[2])},
            "lon_label_counts": {"normal": int(lon[0]), "braking": int(lon[1])},
            "shards": shards,
            "config": to_dict(cfg),
        }
        write_json(tmp / META_FILE, meta)
        check_output_dir(out)
        if out.exists():
            out.rmdir()
        os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    finally:
        release_temporary(tmp)
    return meta


def read_meta(path: str | os.PathLike[str]) -> dict:
    """The meta.json of the dataset folder `path` (InputError if it is not a dataset)."""
    meta_path = Path(path) / META_FILE
    try:
        meta = json.loads(meta_path.read_text())
    except FileNotFoundError:
        raise InputError(f"{path} is not a traffic dataset: no {META_FILE}") from None
    except (OSError, ValueError) as e:
        raise InputError(f"cannot read {meta_path}: {e}") from None
    if not isinstance(meta, dict) or meta.get("layout_version") != LAYOUT_VERSION:
        raise InputError(f"{meta_path}: layout version {meta.get('layout_version') if isinstance(meta, dict) else None!r}, expected {LAYOUT_VERSION}")
    return meta


def read_dataset(path: str | os.PathLike[str]) -> Iterator[dict[str, np.ndarray]]:
    """The shards of a dataset folder, in order, each a dict in the shard layout.

    Raises InputError on a missing or malformed shard, or one holding NaN or inf.
    """
    meta = read_meta(path)
    for entry in meta["shards"]:
        yield read_shard(Path(path) / entry["file"])


def read_shard(file: str | os.PathLike[str]) -> dict[str, np.ndarray]:
    """One shard file, checked against the layout."""
    try:
        with np.load(file) as z:
            missing = [k for k in SHARD_KEYS if k not in z.files]
            shard = {k: z[k] for k in SHARD_KEYS if k not in missing}
    except FileNotFoundError:
        raise InputError(f"missing shard {file}") from None
    except (OSError, ValueError, zipfile.BadZipFile) as e:
        raise InputError(f"cannot read shard {file}: {e}") from None
    if missing:  # numpy's own KeyError names the key inside a longer sentence
        raise InputError(f"shard {file} lacks array {missing[0]!r}")
    s, m = len(shard["hist"]), len(shard["nbr_hist"])
    expected = {
        "hist": ((s, HIST_LEN, 2), np.float32), "fut": ((s, FUT_LEN, 2), np.float32),
        "nbr_hist": ((m, HIST_LEN, 2), np.float32), "nbr_sample": ((m,), np.int32), "nbr_slot": ((m,), np.int8),
        "lat_label": ((s,), np.int8), "lon_label": ((s,), np.int8), "sim_id": ((s,), np.int32),
    }
    for k, (shape, dtype) in expected.items():
        if shard[k].shape != shape or shard[k].dtype != dtype:
            raise InputError(f"shard {file}: {k} is {shard[k].dtype} {shard[k].shape}, expected {np.dtype(dtype)} {shape}")
    for k in ("hist", "fut", "nbr_hist"):
        if not np.isfinite(shard[k]).all():
            raise InputError(f"shard {file}: {k} holds NaN or inf")
    rows = shard["nbr_sample"]
    if m and (rows.min() < 0 or rows.max() >= s or (np.diff(rows) < 0).any()):
        raise InputError(f"shard {file}: nbr_sample must be non-decreasing rows 0..{s - 1}")
    if m and (shard["nbr_slot"].min() < 0 or shard["nbr_slot"].max() >= GRID_SLOTS):
        raise InputError(f"shard {file}: nbr_slot must be grid ids 0..{GRID_SLOTS - 1}")
    if s and not (0 <= shard["lat_label"].min() and shard["lat_label"].max() <= 2 and 0 <= shard["lon_label"].min() and shard["lon_label"].max() <= 1):
        raise InputError(f"shard {file}: labels out of range (lat 0..2, lon 0..1)")
    return shard
