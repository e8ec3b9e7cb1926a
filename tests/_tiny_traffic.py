"""A tiny dataset in the traffic generator's documented layout (the samples of diffsense.train), made
from simple kinematics, so that training can be tested without the generator."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def write(folder: Path, num_sims: int = 4, per_sim: int = 24, seed: int = 0) -> Path:
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    shards = []
    t_hist = 0.2 * np.arange(-15, 1)
    t_fut = 0.2 * np.arange(1, 26)
    for sim in range(num_sims):
        s = per_sim
        speed = rng.uniform(20, 30, size=(s, 1))
        lat_rate = rng.choice([0.0, 0.6, -0.6], size=(s, 1))
        hist = np.stack([speed * t_hist, lat_rate * t_hist], -1)
        fut = np.stack([speed * t_fut + rng.normal(0, 0.3, (s, 25)).cumsum(1), lat_rate * t_fut], -1)
        counts = rng.integers(0, 6, size=s)
        nbr_sample = np.repeat(np.arange(s), counts).astype(np.int32)
        slots = np.concatenate([np.sort(rng.choice([x for x in range(39) if x != 19], c, replace=False)) for c in counts]).astype(np.int8)
        m = len(nbr_sample)
        offset = np.stack([(slots % 13 - 6) * 4.572, (1 - slots // 13) * 3.66], -1)
        nbr_speed = rng.uniform(18, 32, size=(m, 1))
        nbr_hist = offset[:, None, :] + np.stack([nbr_speed * t_hist, np.zeros((m, 16))], -1)
        shard = {
            "hist": hist.astype(np.float32), "fut": fut.astype(np.float32),
            "nbr_hist": nbr_hist.astype(np.float32), "nbr_sample": nbr_sample, "nbr_slot": slots,
            "lat_label": np.where(lat_rate[:, 0] > 0, 1, np.where(lat_rate[:, 0] < 0, 2, 0)).astype(np.int8),
            "lon_label": (speed[:, 0] < 22).astype(np.int8),
            "sim_id": np.full(s, sim, np.int32),
        }
        name = f"shard_{sim:05d}.npz"
        np.savez(folder / name, **shard)
        shards.append({"file": name, "num_samples": s, "num_neighbours": m})
    meta = {"layout_version": 1, "seed": seed, "num_samples": num_sims * per_sim, "shards": shards,
            "config": {"tiny": True}}
    (folder / "meta.json").write_text(json.dumps(meta))
    return folder
