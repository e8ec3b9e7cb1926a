"""One lane change of a recording cut into a scene: the window placed, vehicles sampled, an ego chosen.

The rules are in `_recorded.py`'s module doc; this module carries them out for one lane change.
"""

from __future__ import annotations

import numpy as np

from diffsense.scene._datatypes import BACKGROUND, EGO, LEAD, TARGET, TARGET_LEAD, Scene
from diffsense.scene._recorded_types import FUTURE_S, HISTORY_S, Recording, Track, WindowInfo
from diffsense.scene._simulate import SCENE_DT_S

_EPS = 1e-6  # frame-number round-off of t * rate
CROSSING_MARGIN_S = 2.0  # an automatic window keeps its crossing this close to a prediction instant
_SLIDE_STEP_S = 0.5  # automatic placement tries windows this far apart


def _sample(track: Track, f: np.ndarray, need: int) -> dict[str, np.ndarray] | None:
    """The track at fractional recording frames f [T]; None unless recorded without a gap over
    the first `need` of them. Past its recorded run it continues at its last speed, lane held."""
    lo, hi = int(np.floor(f[0] + _EPS)), int(np.ceil(f[need - 1] - _EPS))
    i = int(np.searchsorted(track.frame, lo))
    j = i + hi - lo
    if j >= track.frame.shape[0] or track.frame[i] != lo or track.frame[j] != hi:
        return None
    end = i + int(np.flatnonzero(np.append(np.diff(track.frame[i:]) != 1, True))[0])  # the run's last index
    frames = track.frame[i:end + 1]
    inside = np.minimum(f, frames[-1])
    out = {name: np.interp(inside, frames, getattr(track, name)[i:end + 1]) for name in ("s_m", "d_m", "speed_mps")}
    if end > i:
        per_frame = track.s_m[end] - track.s_m[end - 1]  # [m / frame]
        out["s_m"] = out["s_m"] + per_frame * np.maximum(f - frames[-1], 0.0)
    held = i + np.minimum(np.floor(f - lo + _EPS).astype(np.int64), end - i)
    out.update(lane=track.lane[held], lane_id=track.lane_id[held])
    return out


def _nearest(s0: np.ndarray, mask: np.ndarray, ahead_of: float | None = None, behind: float | None = None) -> int | None:
    """Index of the nearest vehicle under `mask` ahead of / behind a position at the window start."""
    if ahead_of is not None:
        mask = mask & (s0 > ahead_of)
        return int(np.argmin(np.where(mask, s0, np.inf))) if mask.any() else None
    mask = mask & (s0 < behind)
    return int(np.argmax(np.where(mask, s0, -np.inf))) if mask.any() else None


def _scene_order(s0: np.ndarray, lane0: np.ndarray, target: int, to_id: int, from_id: int) -> tuple[list[int], list[int]] | None:
    """Scene order (ego first, target second) and roles of the kept vehicles, or None without an ego."""
    others = np.arange(s0.shape[0]) != target
    ego = _nearest(s0, others & (lane0 == to_id), behind=s0[target])
    if ego is None:
        ego = _nearest(s0, others & (lane0 == from_id), behind=s0[target])
    if ego is None:
        return None
    order, roles = [ego, target], [EGO, TARGET]
    free = others & (np.arange(s0.shape[0]) != ego)
    for anchor, role in ((ego, LEAD), (target, TARGET_LEAD)):
        found = _nearest(s0, free & (lane0 == lane0[anchor]), ahead_of=s0[anchor])
        if found is not None:
            order.append(found)
            roles.append(role)
            free[found] = False
    rest = np.flatnonzero(free)
    rest = rest[np.argsort(np.abs(s0[rest] - s0[target]), kind="stable")]
    return order + rest.tolist(), roles + [BACKGROUND] * rest.shape[0]


def spans(rec: Recording) -> np.ndarray:
    """[3, tracks]: first frame, last frame and carriageway of every track."""
    return np.array([(t.frame[0], t.frame[-1], t.carriageway) for t in rec.tracks]).reshape(-1, 3).T


def _frames(rec: Recording, crossing_frame: int, window_s: float, crossing_at_s: float) -> np.ndarray:
    num = round(window_s / SCENE_DT_S) + 1
    first = crossing_frame - crossing_at_s * rec.frame_rate_hz
    return np.round(first + np.arange(num) * (rec.frame_rate_hz * SCENE_DT_S), 9)


def _looking(window_s: float) -> int:
    """Frames of a window whose detections feed a prediction: up to the last instant."""
    return round((window_s - FUTURE_S) / SCENE_DT_S + _EPS) + 1


def _build(rec: Recording, samples: list[dict], kept: list[int], order: list[int], roles: list[int], dtype) -> Scene:
    stack = lambda name: np.stack([samples[k][name] for k in order], axis=-1)  # noqa: E731  [T, V]
    s, d = stack("s_m"), stack("d_m")
    heading = np.arctan2(np.gradient(d, SCENE_DT_S, axis=0), np.gradient(s, SCENE_DT_S, axis=0))
    speed = stack("speed_mps") * (np.cos(heading) if rec.speed_is_total else 1.0)
    tracks = [rec.tracks[kept[k]] for k in order]
    per_vehicle = lambda name: np.array([getattr(t, name) for t in tracks])  # noqa: E731
    # Host arrays: a recording is read and cut before the JAX backend starts (its errors first).
    asf = lambda a: np.asarray(a, np.dtype(dtype))  # noqa: E731
    asi = lambda a: np.asarray(a, np.int32)  # noqa: E731
    return Scene(
        s_m=asf(s), d_m=asf(d), x_m=asf(s), y_m=asf(d), heading_rad=asf(heading),
        road_angle_rad=asf(np.zeros_like(s)), speed_mps=asf(speed), lane=asi(stack("lane")),
        length_m=asf(per_vehicle("length_m")), width_m=asf(per_vehicle("width_m")), kind=asi(per_vehicle("kind")),
        role=asi(roles), present=np.ones((len(order),), bool), dt_s=SCENE_DT_S,
    )


def cut_window(rec: Recording, target: int, crossing: int, from_id: int, to_id: int, window_s: float,
               crossing_at_s: float, dtype, track_spans: np.ndarray) -> tuple[Scene, WindowInfo] | str:
    """The scene of one lane change of track `target` (index `crossing`) with its crossing
    `crossing_at_s` into the window, or why there is none ("target_in_view", "no_ego")."""
    tgt = rec.tracks[target]
    f = _frames(rec, int(tgt.frame[crossing]), window_s, crossing_at_s)
    looking = _looking(window_s)
    first, last, way = track_spans
    kept, samples = [], []
    for i in np.flatnonzero((way == tgt.carriageway) & (first <= f[0] + _EPS) & (last >= f[looking - 1] - _EPS)):
        sample = _sample(rec.tracks[i], f, f.shape[0] if i == target else looking)
        if sample is not None:
            kept.append(int(i))
            samples.append(sample)
    if target not in kept:
        return "target_in_view"
    s0 = np.array([x["s_m"][0] for x in samples])
    lane0 = np.array([x["lane_id"][0] for x in samples])
    found = _scene_order(s0, lane0, kept.index(target), to_id, from_id)
    if found is None:
        return "no_ego"
    order, roles = found
    info = WindowInfo(path=rec.path, vehicle_ids=tuple(int(rec.tracks[kept[k]].vehicle_id) for k in order),
                      start_s=float(f[0] / rec.frame_rate_hz), crossing_s=float(tgt.frame[crossing] / rec.frame_rate_hz))
    return _build(rec, samples, kept, order, roles, dtype), info


def crossing_offsets(rec: Recording, target: int, crossing: int, window_s: float) -> list[float]:
    """Where an automatic window may put the crossing [s from its start], best first: as near the
    middle of the prediction instants as the target's time in view allows, within
    CROSSING_MARGIN_S of an instant, every _SLIDE_STEP_S."""
    tgt = rec.tracks[target]
    c = float(tgt.frame[crossing] / rec.frame_rate_hz)
    seen_from, seen_to = tgt.frame[0] / rec.frame_rate_hz, tgt.frame[-1] / rec.frame_rate_hz
    lo = max(0.0, HISTORY_S - CROSSING_MARGIN_S, c + window_s - seen_to)
    hi = min(window_s, window_s - FUTURE_S + CROSSING_MARGIN_S, c - seen_from)
    if lo > hi + _EPS:
        return []
    nominal = min(max(0.5 * (HISTORY_S + window_s - FUTURE_S), lo), hi)
    steps = np.arange(-window_s, window_s + _EPS, _SLIDE_STEP_S)
    offsets = np.unique(np.clip(nominal + steps, lo, hi).round(9))
    return offsets[np.argsort(np.abs(offsets - nominal), kind="stable")].tolist()
