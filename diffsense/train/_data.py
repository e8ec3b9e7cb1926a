"""Training samples: read the generator's sharded dataset into padded arrays in the model frame.

The dataset (see diffsense.train._samples for the layout) is SI road frame; the network trains
in the model frame of the published checkpoints (feet, lateral right), converted here with the
predictor's own boundary functions, so shipped weights and published ones share one convention.
Neighbours are packed per sample into K columns (K = the most any sample has), padding slot -1
and weight 0.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from diffsense.predictors import HIST_LEN, si_to_model
from diffsense.runtime import InputError

# The layout's owner reads and checks shards (shapes, dtypes, finiteness, index ranges).
from diffsense.train._dataset import read_meta, read_shard


@dataclasses.dataclass(frozen=True)
class Samples:
    """S samples, model frame (ft, lateral right) for the network; `fut_m` kept in SI for RMSE.

    hist [S, 16, 2], fut [S, 25, 2], nbr_hist [S, K, 16, 2], nbr_slot int32 [S, K] (-1 padding),
    nbr_weight [S, K] (1 present, 0 padding), lat int32 [S], lon int32 [S], sim_id int64 [S],
    hist_m [S, 16, 2] and fut_m [S, 25, 2] in SI (lon_m, lat_m).
    """

    hist: np.ndarray
    fut: np.ndarray
    nbr_hist: np.ndarray
    nbr_slot: np.ndarray
    nbr_weight: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    sim_id: np.ndarray
    hist_m: np.ndarray
    fut_m: np.ndarray

    def __len__(self) -> int:
        return len(self.hist)

    def take(self, index: np.ndarray) -> Samples:
        return Samples(**{f.name: getattr(self, f.name)[index] for f in dataclasses.fields(self)})


def load_samples(folder: str | Path, max_samples: int = 0) -> tuple[Samples, dict]:
    """All samples of the dataset (the first `max_samples` if > 0), and its meta.json."""
    meta = read_meta(folder)
    parts, total = [], 0
    for entry in meta.get("shards", []):
        if not isinstance(entry, dict) or not isinstance(entry.get("file"), str):
            raise InputError(f"{folder}/meta.json: malformed shard entry {entry!r}")
        parts.append(read_shard(Path(folder) / entry["file"]))
        total += len(parts[-1]["hist"])
        if max_samples and total >= max_samples:
            break
    if total == 0:
        raise InputError(f"{folder}: the dataset holds no samples")
    counts = [np.bincount(p["nbr_sample"], minlength=len(p["hist"])) for p in parts]
    width = max(1, max(int(c.max(initial=0)) for c in counts))
    hist, fut, nbr, slot, weight = [], [], [], [], []
    for part, count in zip(parts, counts):
        s = len(part["hist"])
        rows = part["nbr_sample"].astype(np.int64)
        col = np.arange(len(rows)) - np.concatenate([[0], np.cumsum(count)[:-1]])[rows]
        n = np.zeros((s, width, HIST_LEN, 2), np.float32)
        sl = np.full((s, width), -1, np.int32)
        w = np.zeros((s, width), np.float32)
        n[rows, col], sl[rows, col], w[rows, col] = part["nbr_hist"], part["nbr_slot"], 1.0
        hist.append(part["hist"]), fut.append(part["fut"]), nbr.append(n), slot.append(sl), weight.append(w)
    cat = lambda xs: np.concatenate(xs)[: max_samples or None]  # noqa: E731
    hist_m, fut_m = cat(hist).astype(np.float32), cat(fut).astype(np.float32)
    to_model = lambda a: np.asarray(si_to_model(a), np.float32)  # noqa: E731
    samples = Samples(
        hist=to_model(hist_m),
        fut=to_model(fut_m),
        nbr_hist=to_model(cat(nbr)),
        nbr_slot=cat(slot),
        nbr_weight=cat(weight),
        lat=cat([p["lat_label"] for p in parts]).astype(np.int32),
        lon=cat([p["lon_label"] for p in parts]).astype(np.int32),
        sim_id=cat([p["sim_id"] for p in parts]).astype(np.int64),
        hist_m=hist_m,
        fut_m=fut_m,
    )
    return samples, meta


def split_by_simulation(samples: Samples, val_fraction: float, seed: int) -> tuple[Samples, Samples]:
    """(train, validation): whole simulations go to one side, chosen by a seeded permutation."""
    sims = np.unique(samples.sim_id)
    if len(sims) < 2:
        raise InputError("the dataset must hold at least 2 simulations to hold some out for validation")
    n_val = min(max(1, round(val_fraction * len(sims))), len(sims) - 1)
    val_sims = np.random.default_rng(seed).permutation(sims)[:n_val]
    is_val = np.isin(samples.sim_id, val_sims)
    return samples.take(np.flatnonzero(~is_val)), samples.take(np.flatnonzero(is_val))
