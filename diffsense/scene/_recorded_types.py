"""What a recording is read into and what cutting it gives: tracks, windows and a summary."""

from __future__ import annotations

import dataclasses

import numpy as np

from diffsense.scene._datatypes import Scene

HISTORY_S = 3.0  # the predictor's history (diffsense.tracks.CSLSTM_SPEC.history_s) [s]
FUTURE_S = 5.0  # and its future [s]
MIN_WINDOW_S = HISTORY_S + FUTURE_S  # one prediction instant
# Two seconds of prediction instants around the crossing: a highD vehicle is in view for 12-19 s,
# so a window this long fits most lane changes of a recording (docs/recorded.md).
DEFAULT_WINDOW_S = MIN_WINDOW_S + 2.0
DEFAULT_HOLD_S = 1.0


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


@dataclasses.dataclass(frozen=True)
class Dropped:
    """A lane change that gave no scene: its target's dataset id, the crossing [s] and why."""

    vehicle_id: int
    crossing_s: float
    reason: str  # "target_in_view" (too briefly around the crossing) or "no_ego"


REASONS = {
    "target_in_view": "the target is not in view for a whole window around its crossing",
    "no_ego": "no ego (a vehicle behind the target in its new or old lane) in view while the sensor looks",
}


@dataclasses.dataclass(frozen=True)
class RecordingSummary:
    """What a recording gave: lane changes found, scenes kept, and each dropped one with why."""

    path: str
    lane_changes: int
    scenes: int
    window_s: float
    dropped: tuple[Dropped, ...]

    def line(self) -> str:
        """One line for a log: found, kept, and the count of each reason a lane change was dropped."""
        counts = {r: sum(d.reason == r for d in self.dropped) for r in REASONS}
        why = "; ".join(f"{n} dropped: {REASONS[r]}" for r, n in counts.items() if n)
        return (f"{self.path}: {self.lane_changes} lane change(s), {self.scenes} scene(s) of {self.window_s:g} s"
                + (f" ({why})" if why else ""))


@dataclasses.dataclass(frozen=True)
class RecordedCut:
    """A recording cut into scenes: `scenes[i]` comes from `windows[i]`; `summary` says what was kept."""

    scenes: tuple[Scene, ...]
    windows: tuple[WindowInfo, ...]
    summary: RecordingSummary
