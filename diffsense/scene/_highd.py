"""highD recordings (drone video of German motorways) as scenes.

A recording NN is three CSV files side by side; the columns used here, as the dataset's own
format description and its reference reader (the highD-dataset tools' read_csv.py) name them:

- `NN_tracks.csv`, one row per vehicle and frame: `frame`, `id`, `x`, `y` (the upper-left corner
  of the vehicle's bounding box in image coordinates, x to the right and y downwards [m]),
  `width`, `height` (box size [m]), `xVelocity`, `yVelocity` [m/s], `xAcceleration`,
  `yAcceleration` [m/s^2], `frontSightDistance`, `backSightDistance`, `dhw`, `thw`, `ttc`,
  `precedingXVelocity`, `precedingId`, `followingId`, `leftPrecedingId`, `leftAlongsideId`,
  `leftFollowingId`, `rightPrecedingId`, `rightAlongsideId`, `rightFollowingId`, `laneId`.
  Read: frame, id, x, y, xVelocity, laneId.
- `NN_tracksMeta.csv`, one row per vehicle: `id`, `width` (vehicle length along x [m]),
  `height` (vehicle width [m]), `initialFrame`, `finalFrame`, `numFrames`, `class` (Car or
  Truck), `drivingDirection` (1: upper lanes, driving left, towards -x; 2: lower lanes, driving
  right), `traveledDistance`, `minXVelocity`, `maxXVelocity`, `meanXVelocity`, `minDHW`,
  `minTHW`, `minTTC`, `numLaneChanges`. Read: id, width, height, class, drivingDirection.
- `NN_recordingMeta.csv`, one row: `id`, `frameRate` (25 Hz), `locationId`, `speedLimit`,
  `month`, `weekDay`, `startTime`, `duration`, `totalDrivenDistance`, `totalDrivenTime`,
  `numVehicles`, `numCars`, `numTrucks`, `upperLaneMarkings`, `lowerLaneMarkings` (the image y of
  each carriageway's lane markings [m], ';'-separated, top to bottom). Read: frameRate and the
  markings.

Conversion to the road frame of each carriageway (see _recorded.py for the rest): the vehicle
centre is (x + width / 2, y + height / 2). Direction 2 drives towards +x with its right edge at
the bottom marking y_R: s = x_c, d = y_R - y_c, speed = xVelocity. Direction 1 drives towards -x
with its right edge at the top marking y_R; it is mirrored so that s grows along travel:
s = x_ref - x_c with x_ref the largest x + width in the file (so s >= 0), d = y_c - y_R,
speed = -xVelocity. The motion must be plausible (_recorded_checks.py: the frame rate against
positions and speeds, glitches, speeds, centres on the road). The lane index (0 = rightmost) counts the markings between the right edge
and the centre; lane changes are read from `laneId`. Frame f is at t = f / frameRate.
"""

from __future__ import annotations

from pathlib import Path

import jax.numpy as jnp
import numpy as np

from diffsense.runtime import InputError
from diffsense.scene._datatypes import CAR, TRUCK, Scene
from diffsense.scene._recorded import check_window, group_rows, recorded_scenes
from diffsense.scene._recorded_types import DEFAULT_HOLD_S, DEFAULT_WINDOW_S, Recording, Track
from diffsense.scene._recorded_checks import check_motion, check_road, check_sizes, check_speeds
from diffsense.scene._recorded_csv import integers, read_columns

_KINDS = {"car": CAR, "truck": TRUCK}


def _siblings(tracks_csv: Path) -> tuple[Path, Path]:
    suffix = "_tracks.csv"
    if not tracks_csv.name.endswith(suffix):
        raise InputError(f"{tracks_csv}: a highD tracks file is named NN_tracks.csv (its siblings "
                         "NN_tracksMeta.csv and NN_recordingMeta.csv are found by that name)")
    stem = tracks_csv.name[: -len(suffix)]
    siblings = tracks_csv.with_name(f"{stem}_tracksMeta.csv"), tracks_csv.with_name(f"{stem}_recordingMeta.csv")
    for sibling in siblings:
        if not sibling.is_file():
            raise InputError(f"{tracks_csv}: its sibling file {sibling.name} is missing from {sibling.parent}")
    return siblings


def _markings(path: Path, name: str, cell: str, line: int) -> np.ndarray:
    try:
        values = np.array([float(v) for v in cell.split(";")])
    except ValueError:
        values = np.array([])
    if values.shape[0] < 2 or not np.all(np.isfinite(values)) or not np.all(np.diff(values) > 0):
        raise InputError(f"{path}, line {line}: column {name!r} must be two or more ';'-separated "
                         f"numbers in increasing order, got {cell!r}")
    return values


def _recording_meta(path: Path) -> tuple[float, np.ndarray, np.ndarray]:
    cols, lines = read_columns(path, ("frameRate",), ("upperLaneMarkings", "lowerLaneMarkings"))
    rate = float(cols["frameRate"][0])
    if not rate > 0:
        raise InputError(f"{path}, line {lines[0]}: frameRate must be > 0, got {rate}")
    upper = _markings(path, "upperLaneMarkings", str(cols["upperLaneMarkings"][0]), int(lines[0]))
    lower = _markings(path, "lowerLaneMarkings", str(cols["lowerLaneMarkings"][0]), int(lines[0]))
    return rate, upper, lower


def _tracks_meta(path: Path) -> dict[int, tuple[float, float, int, int]]:
    """id -> (length [m], width [m], kind, driving direction)."""
    cols, lines = read_columns(path, ("id", "width", "height", "drivingDirection"), ("class",))
    ids = integers(path, "id", cols["id"], lines)
    check_sizes(path, cols["width"], cols["height"], lines, ("width", "height"))  # the box's width is along x
    meta = {}
    for i, line in enumerate(lines):
        length, width, direction = cols["width"][i], cols["height"][i], cols["drivingDirection"][i]
        kind = _KINDS.get(str(cols["class"][i]).lower())
        if direction not in (1.0, 2.0):
            raise InputError(f"{path}, line {line}: drivingDirection must be 1 or 2, got {direction}")
        if kind is None:
            raise InputError(f"{path}, line {line}: class must be Car or Truck, got {str(cols['class'][i])!r}")
        meta[int(ids[i])] = (float(length), float(width), kind, int(direction))
    return meta


def read_highd(tracks_csv_path: str | Path) -> Recording:
    """The tracks of a highD recording in the road frame of each carriageway (module doc)."""
    path = Path(tracks_csv_path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    meta_path, recording_path = _siblings(path)
    rate, upper, lower = _recording_meta(recording_path)
    meta = _tracks_meta(meta_path)
    cols, lines = read_columns(path, ("frame", "id", "x", "y", "xVelocity", "laneId"))
    ids = integers(path, "id", cols["id"], lines)
    unknown = ~np.isin(ids, np.fromiter(meta, np.int64, len(meta)))
    if unknown.any():
        bad = int(np.argmax(unknown))
        raise InputError(f"{path}, line {lines[bad]}: vehicle id {ids[bad]} is not in {meta_path.name}")
    frame = integers(path, "frame", cols["frame"], lines)
    lane_id = integers(path, "laneId", cols["laneId"], lines)
    length, width, kind, direction = (np.array([meta[int(v)][k] for v in ids]) for k in range(4))
    x_c, y_c = cols["x"] + 0.5 * length, cols["y"] + 0.5 * width
    lower_lanes = direction == 2
    x_ref = float(np.max(cols["x"] + length))
    s = np.where(lower_lanes, x_c, x_ref - x_c)
    d = np.where(lower_lanes, lower[-1] - y_c, y_c - upper[0])
    speed = np.where(lower_lanes, cols["xVelocity"], -cols["xVelocity"])
    check_speeds(path, speed, lines)
    check_motion(path, ids, frame, x_c, y_c, cols["xVelocity"], rate, lines, f"{recording_path.name}'s frameRate")
    check_road(path, d, np.where(lower_lanes, lower[-1] - lower[0], upper[-1] - upper[0]), lines)
    edges_lower, edges_upper = lower[-1] - lower[::-1], upper - upper[0]  # lane boundaries in d
    lane = np.where(lower_lanes,
                    np.clip(np.searchsorted(edges_lower, d, side="right") - 1, 0, lower.shape[0] - 2),
                    np.clip(np.searchsorted(edges_upper, d, side="right") - 1, 0, upper.shape[0] - 2))
    tracks = []
    for rows in group_rows(ids, frame):
        first = rows[0]
        tracks.append(Track(
            vehicle_id=int(ids[first]), frame=frame[rows], s_m=s[rows], d_m=d[rows], speed_mps=speed[rows],
            lane=lane[rows], lane_id=lane_id[rows], length_m=float(length[first]), width_m=float(width[first]),
            kind=int(kind[first]), carriageway=int(direction[first]),
        ))
    return Recording(path=str(path), frame_rate_hz=rate, tracks=tuple(tracks))


def load_highd(
    tracks_csv_path: str | Path, *, window_s: float = DEFAULT_WINDOW_S, crossing_at_s: float | None = None,
    hold_s: float = DEFAULT_HOLD_S, dtype=jnp.float32,
) -> list[Scene]:
    """One 10 Hz scene per usable lane change of a highD recording (`NN_tracks.csv`; the siblings
    `NN_tracksMeta.csv` and `NN_recordingMeta.csv` are found beside it). See _recorded.py for the
    windows, the ego and the roles."""
    check_window(window_s, crossing_at_s, hold_s)  # before reading a large file
    cut = recorded_scenes(read_highd(tracks_csv_path), window_s=window_s, crossing_at_s=crossing_at_s, hold_s=hold_s, dtype=dtype)
    return list(cut.scenes)
