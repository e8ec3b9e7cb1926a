"""Training samples: read the generator's sharded dataset into padded arrays in the model frame.

The dataset (see diffsense.scene._samples for the layout) is SI road frame; the network trains
in the model frame of the published checkpoints (feet, lateral right), converted here with the
predictor's own boundary functions, so shipped weights and published ones share one convention.
Neighbours are packed per sample into K columns (K = the most any sample has), padding slot -1
and weight 0.
"""

from __future__ import annotations

import dataclasses
import json
import zipfile
from pathlib import Path

import numpy as np

from diffsense.errors import InputError
from diffsense.predict import FUT_LEN, HIST_LEN, N_SLOTS, si_to_model

_SHAPES = {
    "hist": (HIST_LEN, 2),
    "fut": (FUT_LEN, 2),
    "nbr_hist": (HIST_LEN, 2),
    "nbr_sample": (),
    "nbr_slot": (),
    "lat_label": (),
    "lon_label": (),
    "sim_id": (),
}


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


def _read_shard(path: Path) -> dict[str, np.ndarray]:
    try:
        with np.load(path, allow_pickle=False) as z:
            shard = {k: z[k] for k in _SHAPES}
    except FileNotFoundError:
        raise InputError(f"missing shard {path}") from None
    except KeyError as e:
        raise InputError(f"shard {path} lacks array {e}") from None
    except (OSError, ValueError, zipfile.BadZipFile) as e:
        raise InputError(f"cannot read shard {path}: {e}") from None
    s, m = len(shard["hist"]), len(shard["nbr_hist"])
    for key, tail in _SHAPES.items():
        rows = m if key.startswith("nbr_") else s
        if shard[key].shape != (rows,) + tail:
            raise InputError(f"shard {path}: {key} has shape {shard[key].shape}, expected {(rows,) + tail}")
    for key in ("hist", "fut", "nbr_hist"):
        if not np.all(np.isfinite(shard[key])):
            raise InputError(f"shard {path}: {key} holds NaN or inf")
    if m and (shard["nbr_sample"].min() < 0 or shard["nbr_sample"].max() >= s or np.any(np.diff(shard["nbr_sample"]) < 0)):
        raise InputError(f"shard {path}: nbr_sample must be non-decreasing rows 0..{s - 1}")
    if m and (shard["nbr_slot"].min() < 0 or shard["nbr_slot"].max() >= N_SLOTS):
        raise InputError(f"shard {path}: nbr_slot must be grid ids 0..{N_SLOTS - 1}")
    if s and (shard["lat_label"].min() < 0 or shard["lat_label"].max() > 2 or shard["lon_label"].min() < 0 or shard["lon_label"].max() > 1):
        raise InputError(f"shard {path}: labels out of range (lat 0..2, lon 0..1)")
    return shard


def read_meta(folder: str | Path) -> dict:
    """The dataset's meta.json (InputError if the folder is not a dataset)."""
    path = Path(folder) / "meta.json"
    try:
        meta = json.loads(path.read_text())
    except FileNotFoundError:
        raise InputError(f"{folder} is not a traffic dataset (no meta.json); create one with `python -m diffsense.scene generate --out {folder}`") from None
    except (OSError, ValueError) as e:
        raise InputError(f"cannot read {path}: {e}") from None
    if not isinstance(meta, dict) or not isinstance(meta.get("shards"), list):
        raise InputError(f"{path}: no list of shards")
    return meta


def load_samples(folder: str | Path, max_samples: int = 0) -> tuple[Samples, dict]:
    """All samples of the dataset (the first `max_samples` if > 0), and its meta.json."""
    meta = read_meta(folder)
    parts, total = [], 0
    for entry in meta["shards"]:
        if not isinstance(entry, dict) or not isinstance(entry.get("file"), str):
            raise InputError(f"{folder}/meta.json: malformed shard entry {entry!r}")
        parts.append(_read_shard(Path(folder) / entry["file"]))
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
