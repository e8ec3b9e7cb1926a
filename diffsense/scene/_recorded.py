"""Recorded traffic as scenes: lane changes found, windows cut, an ego chosen, all in SI road frame.

A reader (`_highd.py`, `_ngsim.py`) turns a recording into `Track`s at its own frame rate, in
the road frame of its carriageway: s [m] forward along the direction of travel, d [m] to the left
of the carriageway's right edge, the vehicle centre as reference point. From there both formats
follow the same rules:

- Lane changes. A track's lane state changes when a different lane id holds for `hold_s` (1 s)
  without interruption, and the crossing is the first frame of that run. This hysteresis ignores
  the flicker of the lane id of a vehicle riding on a marking (frequent in NGSIM). Only changes
  between adjacent lanes (ids differing by 1) count.
- Windows. Each lane change gives at most one window of `window_s` (10 s: the predictor's 3 s
  of history and 5 s of future, and 2 s of prediction instants between them; at least 8 s). It
  starts `crossing_at_s` before the crossing. Left to itself (`crossing_at_s` None) the window
  puts the crossing in the middle of its prediction instants (4 s in for 10 s) when the target's
  time in view allows, else slides, 0.5 s at a time, as little as it must, keeping the crossing
  within 2 s of a prediction instant; of those windows the first with an ego is taken.
- Resampling. Frame k of a scene is at t0 + k 0.1 s (10 Hz). Positions and speeds are linearly
  interpolated in time between the recording's frames; lanes are held from the last frame at or
  before. At 25 Hz (highD) every second scene frame falls midway between two recorded ones, where
  linear interpolation errs by a h^2 / 8 (h = 0.04 s): 0.2 mm at a = 1 m/s^2, far below the
  recordings' own accuracy. At 10 Hz (NGSIM) the frames are taken as they are.
- Vehicles. The target must be in view (a row at every recorded frame) for the whole window:
  its history and its future are the data. Every other vehicle of its carriageway, the ego
  included, is kept when it is in view while the sensor looks: from the window's start to its
  last prediction instant (`window_s` - 5 s), the frames whose detections feed a prediction.
  A vehicle that leaves the view after that continues at its last recorded speed, lane and
  offset held: those frames feed no number (a test holds E to that). `Scene.present` is per
  vehicle, so a vehicle that enters the view while the sensor looks is dropped (one entering
  the target's grid mid-window is then missing).
- Ego. The vehicle, in view while the sensor looks, whose centre is nearest behind the target's
  centre at the window start in the lane the target changes into (the paper's scenarios: a cut-in
  ahead of the ego), else in the target's original lane. Without one, the lane change gives no
  scene.
- Roles. LEAD is the nearest vehicle ahead of the ego in its lane at the window start,
  TARGET_LEAD the nearest ahead of the target in its lane; the rest are BACKGROUND. Order: ego,
  target, lead, target lead, then by distance to the target at the window start.
- Road. The road is straight with heading 0 and its reference line on the carriageway's right
  edge: x = s, y = d, road angle 0. Heading = atan2(dd/dt, ds/dt) from central differences of the
  10 Hz positions (one-sided at the ends); speed is the speed along the road [m/s].
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from diffsense.runtime import InputError
from diffsense.scene._recorded_types import (
    DEFAULT_HOLD_S,
    DEFAULT_WINDOW_S,
    MIN_WINDOW_S,
    Dropped,
    Recording,
    RecordedCut,
    RecordingSummary,
)
from diffsense.scene._recorded_window import crossing_offsets, cut_window, spans


def group_rows(vehicle_id: np.ndarray, frame: np.ndarray) -> list[np.ndarray]:
    """Row indices of each vehicle in frame order; of rows repeating a (vehicle, frame), the first."""
    order = np.lexsort((frame, vehicle_id))  # stable: file order among equal keys
    v, f = vehicle_id[order], frame[order]
    repeat = np.zeros(order.shape, bool)
    repeat[1:] = (v[1:] == v[:-1]) & (f[1:] == f[:-1])
    order, v = order[~repeat], v[~repeat]
    return np.split(order, np.flatnonzero(v[1:] != v[:-1]) + 1)


def lane_changes(lane_id: np.ndarray, frame: np.ndarray, hold_frames: int) -> list[tuple[int, int, int]]:
    """(index of the crossing, old id, new id) of each lane change of one track (see the module doc)."""
    n = lane_id.shape[0]
    run_start = np.ones(n, bool)
    run_start[1:] = (lane_id[1:] != lane_id[:-1]) | (np.diff(frame) != 1)
    starts = np.flatnonzero(run_start)
    held = np.diff(np.append(starts, n)) >= hold_frames
    starts = starts[held]
    ids = lane_id[starts]
    change = (ids[1:] != ids[:-1]) & (np.abs(ids[1:] - ids[:-1]) == 1)
    return [(int(starts[i + 1]), int(ids[i]), int(ids[i + 1])) for i in np.flatnonzero(change)]


def check_window(window_s: float, crossing_at_s: float | None, hold_s: float) -> None:
    """Refuse window settings that cannot give a scene the predictor can use."""
    if not (isinstance(window_s, (int, float)) and MIN_WINDOW_S <= window_s <= 600.0):
        raise InputError(f"window_s must be in [{MIN_WINDOW_S:g}, 600] s (3 s history + 5 s future at least), "
                         f"got {window_s!r}")
    if crossing_at_s is not None and not (isinstance(crossing_at_s, (int, float)) and 0.0 <= crossing_at_s <= window_s):
        raise InputError(f"crossing_at_s must be in [0, window_s = {window_s:g}] s, got {crossing_at_s!r}")
    if not (isinstance(hold_s, (int, float)) and 0.0 < hold_s <= 60.0):
        raise InputError(f"hold_s must be in (0, 60] s, got {hold_s!r}")


def recorded_scenes(
    rec: Recording, *, window_s: float = DEFAULT_WINDOW_S, crossing_at_s: float | None = None,
    hold_s: float = DEFAULT_HOLD_S, dtype=jnp.float32,
) -> RecordedCut:
    """A scene [T, V] (and where it comes from) for every usable lane change of a recording, and a
    summary of what was kept and why the rest was dropped; `crossing_at_s` None places each
    window to fit (module doc). Refuses a recording that gives no scene, saying why."""
    check_window(window_s, crossing_at_s, hold_s)
    hold = max(1, round(hold_s * rec.frame_rate_hz))
    changes = [(i, *c) for i, t in enumerate(rec.tracks) for c in lane_changes(t.lane_id, t.frame, hold)]
    if not changes:
        raise InputError(f"{rec.path}: no lane change found (a lane id held {hold_s} s after another)")
    scenes, windows, dropped = [], [], []
    track_spans = spans(rec)
    for target, crossing, from_id, to_id in changes:
        offsets = crossing_offsets(rec, target, crossing, window_s) if crossing_at_s is None else [crossing_at_s]
        cut = "target_in_view"
        for offset in offsets:
            cut = cut_window(rec, target, crossing, from_id, to_id, window_s, offset, dtype, track_spans)
            if not isinstance(cut, str):
                break
        if isinstance(cut, str):
            tgt = rec.tracks[target]
            dropped.append(Dropped(int(tgt.vehicle_id), float(tgt.frame[crossing] / rec.frame_rate_hz), cut))
        else:
            scenes.append(cut[0])
            windows.append(cut[1])
    summary = RecordingSummary(rec.path, len(changes), len(scenes), float(window_s), tuple(dropped))
    if not scenes:
        raise InputError(f"{summary.line()}: no scene (a shorter window_s, or another crossing_at_s, may keep some)")
    return RecordedCut(tuple(scenes), tuple(windows), summary)
