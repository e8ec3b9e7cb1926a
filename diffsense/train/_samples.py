"""CS-LSTM training samples from simulated traffic: histories, futures, social grid, labels.

Every vehicle of a simulation is a target at every prediction instant. The 10 Hz recording is
downsampled by 2 to 5 Hz, as NGSIM is for CS-LSTM (Deo & Trivedi 2018), and for a target i at the
prediction instant k (a 5 Hz frame):

- hist [16, 2]: i's positions at k-15 .. k (3 s; the last row is the prediction instant, so it is
  (0, 0)); fut [25, 2]: k+1 .. k+25 (0.2 .. 5 s). Columns (lon_m, lat_m) = (forward, left), SI, in
  i's road-aligned frame relative to i's position at k (the road is straight, so lon = s - s_i(k)
  and lat = d - d_i(k)).
- the social grid: 13 cells of 15 ft = 4.572 m along the road x 3 lanes. A vehicle j is a
  neighbour when the lane its centre is in at k is i's, or one left or right of it, and its centre
  is less than 90 ft = 27.432 m ahead or behind i's: grid id = lane * 13 + cell with lane 0 = left,
  1 = own, 2 = right and cell = round(dlon / 4.572 m) + 6 (0 rearmost). Two vehicles fall into
  one cell only when both are shorter than 15 ft and nearly touching; then the one nearer the
  cell centre is kept (the reference keeps whichever it saw last). A neighbour's history covers the same 16 instants, in the same frame as i's (relative to
  i at k).
- lateral label (reference rule): with the centre lane at k - 4 s, k and k + 4 s, right (2) if
  the lane at k+4 s is right of the lane at k or the lane at k is right of the one at k-4 s; else
  left (1) by the mirrored rule; else keep (0). The reference checks "right" first.
- longitudinal label (reference rule): braking (1) if the average speed over the next 5 s is below
  0.8 times the average speed over the last 3 s (the reference's "current speed"), else normal (0).

Dataset layout (written by `write_dataset`, read by `read_dataset`): a folder holding
`meta.json` and shards `shard_00000.npz`, `shard_00001.npz`, ... (uncompressed `np.savez`), each
with S samples and M neighbours in all:

    hist        float32 [S, 16, 2]  target history, (lon_m, lat_m), relative to the target at k
    fut         float32 [S, 25, 2]  target future, same frame
    nbr_hist    float32 [M, 16, 2]  neighbour histories, same frame (relative to the target at k)
    nbr_sample  int32   [M]         row (within the shard) of the sample a neighbour belongs to,
                                    non-decreasing
    nbr_slot    int8    [M]         grid id 0..38 (lane * 13 + cell; lane 0 left, 1 own, 2 right)
    lat_label   int8    [S]         0 keep, 1 left, 2 right
    lon_label   int8    [S]         0 normal, 1 braking
    sim_id      int32   [S]         global index of the simulation the sample comes from (samples
                                    of one simulation are correlated: split train/validation by it)

`meta.json` holds the layout version, the generator config, the seed, the counts (samples,
neighbours, simulations, label histograms) and the list of shards with their sample counts.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from diffsense.scene import SCENE_DT_S, TrafficTrajectories
from diffsense.tracks import CSLSTM_SPEC

# The sample layout is the CS-LSTM's input spec (one source: diffsense.predictors.CSLSTM_SPEC).
LAYOUT_VERSION = 1
DOWNSAMPLE = CSLSTM_SPEC.frames_per_point(SCENE_DT_S)  # 10 Hz -> 5 Hz
HIST_LEN = CSLSTM_SPEC.history_points  # 3 s at 5 Hz, the last point at the prediction instant
FUT_LEN = CSLSTM_SPEC.future_points  # 5 s at 5 Hz
GRID_CELL_M = CSLSTM_SPEC.grid_cell_m  # 15 ft
GRID_CELLS = CSLSTM_SPEC.grid_cells
GRID_LANES = CSLSTM_SPEC.grid_lanes
GRID_SLOTS = CSLSTM_SPEC.grid_size
GRID_REACH_M = (GRID_CELLS // 2) * GRID_CELL_M  # 90 ft: neighbours strictly closer than this along the road
_PER_S = int(CSLSTM_SPEC.rate_hz)
LAT_WINDOW = 4 * _PER_S  # 4 s either side (lateral label, the reference's rule)
LON_HIST = HIST_LEN - 1  # 3 s back (longitudinal label's current speed)
LON_FUT = FUT_LEN  # 5 s ahead
BRAKING_RATIO = 0.8
KEEP, LEFT, RIGHT = 0, 1, 2
NORMAL, BRAKING = 0, 1
FIRST_INSTANT = LAT_WINDOW  # 5 Hz frame of the first instant: 4 s of recording before it


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class DenseSamples:
    """Samples with the dense social grid (the predictor's dense form); leading S samples.

    Attributes:
        hist: [S, 16, 2] target history (lon_m, lat_m) relative to the target at the instant.
        fut: [S, 25, 2] target future, same frame.
        nbr_hist: [S, 39, 16, 2] neighbour histories by grid id, same frame; zeros where empty.
        nbr_present: [S, 39] True where a neighbour occupies the grid cell.
        lat_label: [S] KEEP, LEFT or RIGHT.
        lon_label: [S] NORMAL or BRAKING.
    """

    hist: Float[Array, "S 16 2"]
    fut: Float[Array, "S 25 2"]
    nbr_hist: Float[Array, "S 39 16 2"]
    nbr_present: Bool[Array, "S 39"]
    lat_label: Int[Array, " S"]
    lon_label: Int[Array, " S"]


def lateral_label(lane_before: Int[Array, "*S"], lane_now: Int[Array, "*S"], lane_after: Int[Array, "*S"]) -> Int[Array, "*S"]:
    """Reference lateral manoeuvre from the lane 4 s before, now and 4 s after (0 = rightmost lane).

    Right if the vehicle moves (or has moved) to a lower lane index, else left if to a higher one,
    else keep; "right" is checked first, as in the reference preprocessing.
    """
    right = (lane_after < lane_now) | (lane_now < lane_before)
    left = (lane_after > lane_now) | (lane_now > lane_before)
    return jnp.where(right, RIGHT, jnp.where(left, LEFT, KEEP)).astype(jnp.int32)


def longitudinal_label(s_3s_before_m: Float[Array, "*S"], s_now_m: Float[Array, "*S"], s_5s_after_m: Float[Array, "*S"]) -> Int[Array, "*S"]:
    """Reference longitudinal manoeuvre: braking when the mean speed over the next 5 s is below
    0.8 x the mean speed over the last 3 s (positions along the road [m])."""
    speed_hist = (s_now_m - s_3s_before_m) / (LON_HIST / CSLSTM_SPEC.rate_hz)
    speed_fut = (s_5s_after_m - s_now_m) / (LON_FUT / CSLSTM_SPEC.rate_hz)
    return jnp.where(speed_fut < BRAKING_RATIO * speed_hist, BRAKING, NORMAL).astype(jnp.int32)


def num_instants(window_s: float, instant_every_s: float) -> int:
    """Prediction instants per vehicle in a window of `window_s` [-]."""
    return int(round(window_s / instant_every_s + 1e-9)) + 1


def extract_samples(
    traj: TrafficTrajectories, lane_width_m: float, window_s: float, instant_every_s: float
) -> DenseSamples:
    """Samples of one simulation ([T, V] trajectories at 10 Hz, T = (4 + window_s + 5) s * 10 + 1).

    The prediction instants are 4 s, 4 s + instant_every_s, ..., 4 s + window_s after the start of
    the recording; the samples are ordered instant-major: row = instant * V + vehicle.
    """
    s = traj.s_m[::DOWNSAMPLE]
    d = traj.d_m[::DOWNSAMPLE]
    lane = traj.centre_lane(lane_width_m)[::DOWNSAMPLE]
    ring = traj.vehicles.ring_length_m
    stride = int(round(instant_every_s * CSLSTM_SPEC.rate_hz))
    count = num_instants(window_s, instant_every_s)
    if FIRST_INSTANT + (count - 1) * stride + FUT_LEN > s.shape[0] - 1:
        raise ValueError(f"recording of {s.shape[0]} frames at 5 Hz is too short for a {window_s} s window")
    instants = FIRST_INSTANT + stride * jnp.arange(count)
    per_instant = jax.vmap(lambda k: _at_instant(s, d, lane, ring, k))(instants)
    return jax.tree_util.tree_map(lambda a: a.reshape((-1,) + a.shape[2:]), per_instant)


def _at_instant(s, d, lane, ring, k) -> DenseSamples:
    """All V targets of one simulation at the 5 Hz frame k."""
    num_v = s.shape[1]
    window = jax.lax.dynamic_slice_in_dim
    s_hist, d_hist = window(s, k - HIST_LEN + 1, HIST_LEN).T, window(d, k - HIST_LEN + 1, HIST_LEN).T  # [V, 16]
    s_fut, d_fut = window(s, k + 1, FUT_LEN).T, window(d, k + 1, FUT_LEN).T  # [V, 25]
    s_now, d_now, lane_now = s[k], d[k], lane[k]
    hist = jnp.stack([s_hist - s_now[:, None], d_hist - d_now[:, None]], axis=-1)
    fut = jnp.stack([s_fut - s_now[:, None], d_fut - d_now[:, None]], axis=-1)

    # The grid at k: nearest image of j on the ring, lane offset, cell; one vehicle per cell.
    raw = s_now[None, :] - s_now[:, None]  # [i, j]
    dlon = jnp.mod(raw + 0.5 * ring, ring) - 0.5 * ring
    dlane = lane_now[None, :] - lane_now[:, None]
    valid = (jnp.abs(dlane) <= 1) & (jnp.abs(dlon) < GRID_REACH_M) & ~jnp.eye(num_v, dtype=bool)
    cell = jnp.clip(jnp.round(dlon / GRID_CELL_M).astype(jnp.int32) + GRID_CELLS // 2, 0, GRID_CELLS - 1)
    slot = jnp.where(valid, (1 - dlane) * GRID_CELLS + cell, GRID_SLOTS)  # GRID_SLOTS: a spill column
    off_centre_mm = jnp.round(jnp.abs(dlon - (cell - GRID_CELLS // 2) * GRID_CELL_M) * 1000.0).astype(jnp.int32)
    key = jnp.where(valid, off_centre_mm * _KEY_BASE + jnp.arange(num_v, dtype=jnp.int32)[None, :], _EMPTY)
    rows = jnp.broadcast_to(jnp.arange(num_v)[:, None], slot.shape)
    best = jnp.full((num_v, GRID_SLOTS + 1), _EMPTY, jnp.int32).at[rows, slot].min(key)[:, :GRID_SLOTS]
    present = best < _EMPTY
    nbr = jnp.where(present, best % _KEY_BASE, 0)  # [i, slot] vehicle index

    image = jnp.take_along_axis(raw - dlon, nbr, axis=1)  # multiple of the ring to subtract
    nbr_s = s_hist[nbr] - s_now[:, None, None] - image[:, :, None]  # [i, slot, 16]
    nbr_d = d_hist[nbr] - d_now[:, None, None]
    nbr_hist = jnp.where(present[:, :, None, None], jnp.stack([nbr_s, nbr_d], axis=-1), 0.0)

    lat = lateral_label(lane[k - LAT_WINDOW], lane_now, lane[k + LAT_WINDOW])
    lon = longitudinal_label(s[k - LON_HIST], s_now, s[k + LON_FUT])
    return DenseSamples(hist=hist, fut=fut, nbr_hist=nbr_hist, nbr_present=present, lat_label=lat, lon_label=lon)


_KEY_BASE = 1024  # vehicles per simulation must stay below this (the config allows 8 x 64 = 512)
_EMPTY = np.iinfo(np.int32).max


def compact_samples(dense: DenseSamples, sim_id: np.ndarray) -> dict[str, np.ndarray]:
    """The shard layout (module docstring) from dense samples [S, ...] on the host."""
    present = np.asarray(dense.nbr_present)
    sample, slot = np.nonzero(present)  # row-major: sorted by sample, then by slot
    return {
        "hist": np.asarray(dense.hist, np.float32),
        "fut": np.asarray(dense.fut, np.float32),
        "nbr_hist": np.asarray(dense.nbr_hist, np.float32)[sample, slot],
        "nbr_sample": sample.astype(np.int32),
        "nbr_slot": slot.astype(np.int8),
        "lat_label": np.asarray(dense.lat_label, np.int8),
        "lon_label": np.asarray(dense.lon_label, np.int8),
        "sim_id": np.asarray(sim_id, np.int32),
    }
