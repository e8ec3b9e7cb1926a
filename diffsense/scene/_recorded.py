"""Recorded traffic as scenes: lane changes found, windows cut, an ego chosen, all in SI road frame.

A reader (`_highd.py`, `_ngsim.py`) turns a recording into `Track`s at its own frame rate, in
the road frame of its carriageway: s [m] forward along the direction of travel, d [m] to the left
of the carriageway's right edge, the vehicle centre as reference point. From there both formats
follow the same rules:

- Lane changes. A track's lane state changes when a different lane id holds for `hold_s` (1 s)
  without interruption, and the crossing is the first frame of that run. This hysteresis ignores
  the flicker of the lane id of a vehicle riding on a marking (frequent in NGSIM). Only changes
  between adjacent lanes (ids differing by 1) count.
- Windows. Each lane change gives a window of `duration_s` (20 s, the length of the synthetic
  scenarios in configs/scenarios) that starts `crossing_at_s` (5 s) before the crossing: close to
  the nominal sc01 cut-in, which crosses the lane boundary at 3 + 4.5 / 2 = 5.25 s. At least
  3 s of history and 5 s of future must fit (the predictor's), so duration_s >= 8 s.
- Resampling. Frame k of a scene is at t0 + k 0.1 s (10 Hz). Positions and speeds are linearly
  interpolated in time between the recording's frames; lanes are held from the last frame at or
  before. At 25 Hz (highD) every second scene frame falls midway between two recorded ones, where
  linear interpolation errs by a h^2 / 8 (h = 0.04 s): 0.2 mm at a = 1 m/s^2, far below the
  recordings' own accuracy. At 10 Hz (NGSIM) the frames are taken as they are.
- Vehicles. A scene keeps every vehicle of the target's carriageway that has a row at every
  recorded frame the window spans. `Scene.present` is per vehicle, so a vehicle seen for only
  part of the window is dropped (one entering the target's grid mid-window is then missing).
- Ego. The vehicle, present for the whole window, whose centre is nearest behind the target's
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

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from diffsense.runtime import InputError
from diffsense.scene._datatypes import BACKGROUND, EGO, LEAD, TARGET, TARGET_LEAD, Scene
from diffsense.scene._simulate import SCENE_DT_S

DEFAULT_DURATION_S = 20.0
DEFAULT_CROSSING_AT_S = 5.0
DEFAULT_HOLD_S = 1.0
MIN_DURATION_S = 8.0  # 3 s of history and 5 s of future
_EPS = 1e-6  # frame-number round-off of t * rate


@dataclasses.dataclass(frozen=True)
class Track:
    """One vehicle of a recording at the recording's rate (frames strictly increasing)."""

    vehicle_id: int
    frame: np.ndarray  # [n] recording frame numbers
    s_m: np.ndarray  # [n] along the direction of travel [m]
    d_m: np.ndarray  # [n] left of the carriageway's right edge [m]
    speed_mps: np.ndarray  # [n] as recorded: along the road, or total (see Recording)
    lane: np.ndarray  # [n] lane index, 0 = rightmost
    lane_id: np.ndarray  # [n] the dataset's lane id (its changes are lane changes)
    length_m: float
    width_m: float
    kind: int  # CAR, VAN or TRUCK
    carriageway: int  # vehicles of another carriageway never share a scene


@dataclasses.dataclass(frozen=True)
class Recording:
    """The tracks of one recording; `speed_is_total` when speeds include the lateral part."""

    path: str
    frame_rate_hz: float
    tracks: tuple[Track, ...]
    speed_is_total: bool = False


@dataclasses.dataclass(frozen=True)
class WindowInfo:
    """Where a scene comes from: dataset vehicle ids in scene order (ego, target, ...) and times [s]."""

    path: str
    vehicle_ids: tuple[int, ...]
    start_s: float
    crossing_s: float


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


def _sample(track: Track, f: np.ndarray) -> dict[str, np.ndarray] | None:
    """The track at fractional recording frames f [T], or None unless present at all of them."""
    lo, hi = int(np.floor(f[0] + _EPS)), int(np.ceil(f[-1] - _EPS))
    i = int(np.searchsorted(track.frame, lo))
    j = i + hi - lo
    if j >= track.frame.shape[0] or track.frame[i] != lo or track.frame[j] != hi:
        return None
    frames = track.frame[i:j + 1]
    held = i + np.floor(f - lo + _EPS).astype(np.int64)
    out = {name: np.interp(f, frames, getattr(track, name)[i:j + 1]) for name in ("s_m", "d_m", "speed_mps")}
    out.update(lane=track.lane[held], lane_id=track.lane_id[held])
    return out


def _nearest(s0: np.ndarray, mask: np.ndarray, ahead_of: float | None = None, behind: float | None = None) -> int | None:
    """Index of the nearest vehicle under `mask` ahead of / behind a position at the window start."""
    if ahead_of is not None:
        mask = mask & (s0 > ahead_of)
        key = np.where(mask, s0, np.inf)
        return int(np.argmin(key)) if mask.any() else None
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


def _frames(rec: Recording, crossing_frame: int, duration_s: float, crossing_at_s: float) -> np.ndarray:
    num = round(duration_s / SCENE_DT_S) + 1
    first = crossing_frame - crossing_at_s * rec.frame_rate_hz
    return np.round(first + np.arange(num) * (rec.frame_rate_hz * SCENE_DT_S), 9)


def _spans(rec: Recording) -> np.ndarray:
    """[3, tracks]: first frame, last frame and carriageway of every track."""
    return np.array([(t.frame[0], t.frame[-1], t.carriageway) for t in rec.tracks]).reshape(-1, 3).T


def cut_window(rec: Recording, target: int, crossing: int, from_id: int, to_id: int,
               duration_s: float, crossing_at_s: float, dtype, spans: np.ndarray | None = None,
               ) -> tuple[Scene, WindowInfo] | None:
    """The scene of one lane change of track `target` (index `crossing`), or None (module doc)."""
    tgt = rec.tracks[target]
    f = _frames(rec, int(tgt.frame[crossing]), duration_s, crossing_at_s)
    first, last, way = _spans(rec) if spans is None else spans
    kept, samples = [], []
    for i in np.flatnonzero((way == tgt.carriageway) & (first <= f[0] + _EPS) & (last >= f[-1] - _EPS)):
        sample = _sample(rec.tracks[i], f)
        if sample is not None:
            kept.append(int(i))
            samples.append(sample)
    if target not in kept:
        return None
    s0 = np.array([x["s_m"][0] for x in samples])
    lane0 = np.array([x["lane_id"][0] for x in samples])
    found = _scene_order(s0, lane0, kept.index(target), to_id, from_id)
    if found is None:
        return None
    order, roles = found
    stack = lambda name: np.stack([samples[k][name] for k in order], axis=-1)  # noqa: E731  [T, V]
    s, d = stack("s_m"), stack("d_m")
    vs, vd = np.gradient(s, SCENE_DT_S, axis=0), np.gradient(d, SCENE_DT_S, axis=0)
    heading = np.arctan2(vd, vs)
    speed = stack("speed_mps") * (np.cos(heading) if rec.speed_is_total else 1.0)
    tracks = [rec.tracks[kept[k]] for k in order]
    per_vehicle = lambda name: np.array([getattr(t, name) for t in tracks])  # noqa: E731
    # numpy converts and device_put moves: jnp.asarray would compile once per scene shape.
    asf = lambda a: jax.device_put(np.asarray(a, np.dtype(dtype)))  # noqa: E731
    asi = lambda a: jax.device_put(np.asarray(a, np.int32))  # noqa: E731
    scene = Scene(
        s_m=asf(s), d_m=asf(d), x_m=asf(s), y_m=asf(d), heading_rad=asf(heading),
        road_angle_rad=asf(np.zeros_like(s)), speed_mps=asf(speed),
        lane=asi(stack("lane")), length_m=asf(per_vehicle("length_m")),
        width_m=asf(per_vehicle("width_m")), kind=asi(per_vehicle("kind")),
        role=asi(roles), present=jax.device_put(np.ones((len(order),), bool)), dt_s=SCENE_DT_S,
    )
    info = WindowInfo(path=rec.path, vehicle_ids=tuple(int(t.vehicle_id) for t in tracks),
                      start_s=float(f[0] / rec.frame_rate_hz),
                      crossing_s=float(tgt.frame[crossing] / rec.frame_rate_hz))
    return scene, info


def check_window(duration_s: float, crossing_at_s: float, hold_s: float) -> None:
    """Refuse window settings that cannot give a scene the predictor can use."""
    if not duration_s >= MIN_DURATION_S:
        raise InputError(f"duration_s must be at least {MIN_DURATION_S} s (3 s history + 5 s future), got {duration_s}")
    if not 0.0 <= crossing_at_s <= duration_s:
        raise InputError(f"crossing_at_s must be in [0, duration_s = {duration_s}] s, got {crossing_at_s}")
    if not hold_s > 0.0:
        raise InputError(f"hold_s must be > 0 s, got {hold_s}")


def recorded_scenes(
    rec: Recording, *, duration_s: float = DEFAULT_DURATION_S, crossing_at_s: float = DEFAULT_CROSSING_AT_S,
    hold_s: float = DEFAULT_HOLD_S, dtype=jnp.float32,
) -> tuple[list[Scene], list[WindowInfo]]:
    """A scene [T, V] (and where it comes from) for every usable lane change of a recording."""
    check_window(duration_s, crossing_at_s, hold_s)
    hold = max(1, round(hold_s * rec.frame_rate_hz))
    changes = [(i, *c) for i, t in enumerate(rec.tracks) for c in lane_changes(t.lane_id, t.frame, hold)]
    if not changes:
        raise InputError(f"{rec.path}: no lane change found (a lane id held {hold_s} s after another)")
    scenes, infos = [], []
    spans = _spans(rec)
    for change in changes:
        cut = cut_window(rec, *change, duration_s, crossing_at_s, dtype, spans)
        if cut is not None:
            scenes.append(cut[0])
            infos.append(cut[1])
    if not scenes:
        raise InputError(f"{rec.path}: {len(changes)} lane change(s) found, none with the target and an ego "
                         f"present for the whole {duration_s} s window starting {crossing_at_s} s before it")
    return scenes, infos
