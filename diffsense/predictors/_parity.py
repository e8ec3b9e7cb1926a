"""Run the network on a batch in the PyTorch reference's own layout and return its outputs.

Reference layout (ngsimDataset.collate_fn / highwayNet.forward, evaluation mode):
  hist [16, B, 2], nbrs [16, N, 2] (every present neighbour, ordered by sample then grid id,
  lane-major), mask [B, 3, 13, 64] bool (True over all 64 channels of each occupied cell);
  model frame (feet, lateral right). Outputs: fut_pred [25, B, 5] (single-mode) or
  [6, 25, B, 5] (manoeuvre, lon-major) with lat_pred [B, 3] and lon_pred [B, 2].
"""

from __future__ import annotations

import jax
import numpy as np

from diffsense.predictors._api import CSLSTMPredictor, predict_model_frame
from diffsense.predictors._model import ENC_SIZE, HIST_LEN, N_CELLS, N_LANES, N_SLOTS
from diffsense.runtime import InputError


def reference_to_compact(hist, nbrs, mask, source: str = "inputs"):
    """(hist [B,16,2], nbr_hist [B,N,16,2], nbr_slot [B,N] (-1 = padding), nbr_weight [B,N])."""
    hist, nbrs, mask = np.asarray(hist), np.asarray(nbrs), np.asarray(mask)
    if hist.ndim != 3 or hist.shape[0] != HIST_LEN or hist.shape[2] != 2:
        raise InputError(f"{source}: hist must be [16, B, 2], got {list(hist.shape)}")
    b = hist.shape[1]
    if mask.shape != (b, N_LANES, N_CELLS, ENC_SIZE) or mask.dtype != np.bool_:
        raise InputError(f"{source}: mask must be bool [{b}, 3, 13, 64], got {mask.dtype} {list(mask.shape)}")
    if not np.all(mask == mask[..., :1]):
        raise InputError(f"{source}: mask must be constant over its last (channel) axis")
    occupied = mask[..., 0].reshape(b, N_SLOTS)  # lane-major grid ids, as masked_scatter_ fills
    n = int(occupied.sum())
    if nbrs.ndim != 3 or nbrs.shape[0] != HIST_LEN or nbrs.shape[2] != 2 or nbrs.shape[1] != n:
        raise InputError(f"{source}: nbrs must be [16, {n}, 2] (one per True cell of mask), got {list(nbrs.shape)}")
    for name, arr in (("hist", hist), ("nbrs", nbrs)):
        if not np.issubdtype(arr.dtype, np.floating) or not np.all(np.isfinite(arr)):
            raise InputError(f"{source}: {name} must be finite floating-point numbers")
    rows, slots = np.nonzero(occupied)  # row-major: sample, then grid id = the order of nbrs
    per_row = np.bincount(rows, minlength=b)
    width = max(int(per_row.max(initial=0)), 1)
    nbr_hist = np.zeros((b, width, HIST_LEN, 2), np.float32)
    nbr_slot = np.full((b, width), -1, np.int32)
    nbr_weight = np.zeros((b, width), np.float32)
    col = np.arange(n) - np.concatenate([[0], np.cumsum(per_row)[:-1]])[rows]
    nbr_hist[rows, col] = np.moveaxis(nbrs, 0, 1)
    nbr_slot[rows, col] = slots
    nbr_weight[rows, col] = 1.0
    return np.moveaxis(hist, 0, 1).astype(np.float32), nbr_hist, nbr_slot, nbr_weight


_forward = jax.jit(predict_model_frame)


def reference_forward(predictor: CSLSTMPredictor, hist, nbrs, mask, source: str = "inputs") -> dict[str, np.ndarray]:
    """What the reference highwayNet returns in evaluation mode, as numpy arrays by name."""
    pred = _forward(predictor, *reference_to_compact(hist, nbrs, mask, source))
    fut = np.asarray(pred.fut).transpose(1, 2, 0, 3)  # [K, 25, B, 5]
    if not predictor.maneuvers:
        return {"fut_pred": fut[0]}
    return {"fut_pred": fut, "lat_pred": np.asarray(pred.lat_prob), "lon_pred": np.asarray(pred.lon_prob)}
