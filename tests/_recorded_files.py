"""Tiny highD and NGSIM recordings of the same motion, written in the datasets' column layouts.

Six vehicles on a three-lane carriageway of 12 ft lanes (lane 0 = rightmost), for 30 s:
1 the target, lane 2 -> lane 1 by a quintic from 7.97 s to 11.97 s (crossing the marking at
9.97 s, so the first recorded frame in lane 1 is at 10.0 s in both formats); 2 the ego, lane 1,
26.25 m behind the target at 5 s and accelerating at 0.3 m/s^2; 3 a decoy in the target's
original lane, nearer behind it than the ego; 4 a truck leading the ego; 5 the target's lead;
6 a vehicle riding on the lane 0/1 marking (its lane id flickers every 0.4 s) seen only for 8 s.
highD files add vehicle 7 on the other carriageway. The motion is written in closed form here
and converted to each format's units and axes (metres at 25 Hz, feet at 10 Hz).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

FOOT_M = 0.3048
LANE_M = 12.0 * FOOT_M
DURATION_S = 30.0
UPPER = [2.0 + i * LANE_M for i in range(4)]  # image y of the upper carriageway's markings [m]
LOWER = [16.0 + i * LANE_M for i in range(4)]
IMAGE_X_M = 600.0  # where the mirrored carriageway's s is measured from

HIGHD_TRACKS = ["frame", "id", "x", "y", "width", "height", "xVelocity", "yVelocity", "xAcceleration",
                "yAcceleration", "frontSightDistance", "backSightDistance", "dhw", "thw", "ttc",
                "precedingXVelocity", "precedingId", "followingId", "leftPrecedingId", "leftAlongsideId",
                "leftFollowingId", "rightPrecedingId", "rightAlongsideId", "rightFollowingId", "laneId"]
HIGHD_META = ["id", "width", "height", "initialFrame", "finalFrame", "numFrames", "class", "drivingDirection",
              "traveledDistance", "minXVelocity", "maxXVelocity", "meanXVelocity", "minDHW", "minTHW",
              "minTTC", "numLaneChanges"]
HIGHD_RECORDING = ["id", "frameRate", "locationId", "speedLimit", "month", "weekDay", "startTime", "duration",
                   "totalDrivenDistance", "totalDrivenTime", "numVehicles", "numCars", "numTrucks",
                   "upperLaneMarkings", "lowerLaneMarkings"]
NGSIM = ["Vehicle_ID", "Frame_ID", "Total_Frames", "Global_Time", "Local_X", "Local_Y", "Global_X", "Global_Y",
         "v_Length", "v_Width", "v_Class", "v_Vel", "v_Acc", "Lane_ID", "Preceding", "Following",
         "Space_Headway", "Time_Headway"]


def _quintic(t, start, duration, d0, d1):
    u = np.clip((t - start) / duration, 0.0, 1.0)
    d = d0 + (d1 - d0) * (10 * u**3 - 15 * u**4 + 6 * u**5)
    rate = (d1 - d0) * (30 * u**2 - 60 * u**3 + 30 * u**4) / duration
    return d, rate


def motion(vehicle: int, t: np.ndarray):
    """(s [m], d [m], ds/dt, dd/dt) of a vehicle at times t [s]."""
    one = np.ones_like(t)
    if vehicle == 1:
        d, rate = _quintic(t, 7.97, 4.0, 2.5 * LANE_M, 1.5 * LANE_M)
        return 100.0 + 20.0 * t, d, 20.0 * one, rate
    if vehicle == 2:
        return 75.0 + 19.0 * t + 0.15 * t**2, 1.5 * LANE_M * one, 19.0 + 0.3 * t, 0.0 * one
    if vehicle == 6:
        side = np.where(np.floor(t / 0.4) % 2 == 0, 0.1, -0.1)
        return 60.0 + 18.0 * t, LANE_M + side, 18.0 * one, 0.0 * one
    s0, v, lane = {3: (90.0, 20.0, 2), 4: (130.0, 19.5, 1), 5: (140.0, 21.0, 2), 7: (50.0, 25.0, 0)}[vehicle]
    return s0 + v * t, (lane + 0.5) * LANE_M * one, v * one, 0.0 * one


SIZES = {1: (4.5, 1.8), 2: (4.8, 1.9), 3: (4.2, 1.7), 4: (12.0, 2.5), 5: (5.0, 2.0), 6: (4.4, 1.8), 7: (4.6, 1.8)}
TRUCKS = {4}
SEEN_S = {6: (0.0, 8.0)}  # vehicles not seen for the whole recording


def _times(vehicle: int, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = SEEN_S.get(vehicle, (0.0, DURATION_S))
    frames = np.arange(round(lo * rate_hz), round(hi * rate_hz) + 1)
    return frames, frames / rate_hz


def _write(path: Path, header: list[str], rows: list[dict]) -> Path:
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        for row in rows:
            writer.writerow([row.get(name, 0) for name in header])
    return path


def write_highd(folder: Path, direction: int = 2, drop: tuple[int, ...] = (), stem: str = "01") -> Path:
    """NN_tracks.csv, NN_tracksMeta.csv, NN_recordingMeta.csv; vehicles 1-6 drive in `direction`."""
    tracks, meta = [], []
    for vehicle in (v for v in SIZES if v not in drop):
        way = direction if vehicle != 7 else 3 - direction
        length, width = SIZES[vehicle]
        frames, t = _times(vehicle, 25.0)
        s, d, vs, vd = motion(vehicle, t)
        lane = np.floor(d / LANE_M).astype(int)
        if way == 2:  # towards +x, right edge at the bottom marking
            x_c, y_c, vx, vy, lane_id = s, LOWER[-1] - d, vs, -vd, 8 - lane
        else:  # towards -x, right edge at the top marking
            x_c, y_c, vx, vy, lane_id = IMAGE_X_M - s, UPPER[0] + d, -vs, vd, 2 + lane
        for k in range(frames.shape[0]):
            tracks.append({"frame": frames[k], "id": vehicle, "x": f"{x_c[k] - length / 2:.6f}",
                           "y": f"{y_c[k] - width / 2:.6f}", "width": length, "height": width,
                           "xVelocity": f"{vx[k]:.6f}", "yVelocity": f"{vy[k]:.6f}", "laneId": lane_id[k]})
        meta.append({"id": vehicle, "width": length, "height": width, "initialFrame": frames[0],
                     "finalFrame": frames[-1], "numFrames": frames.shape[0],
                     "class": "Truck" if vehicle in TRUCKS else "Car", "drivingDirection": way})
    recording = {"id": 1, "frameRate": 25, "locationId": 1, "speedLimit": -1, "month": "09.2017",
                 "weekDay": "Tue", "startTime": "08:38", "duration": DURATION_S,
                 "upperLaneMarkings": ";".join(f"{y:.4f}" for y in UPPER),
                 "lowerLaneMarkings": ";".join(f"{y:.4f}" for y in LOWER)}
    _write(folder / f"{stem}_tracksMeta.csv", HIGHD_META, meta)
    _write(folder / f"{stem}_recordingMeta.csv", HIGHD_RECORDING, [recording])
    return _write(folder / f"{stem}_tracks.csv", HIGHD_TRACKS, tracks)


def write_ngsim(folder: Path, drop: tuple[int, ...] = (), name: str = "trajectories.csv") -> Path:
    """An NGSIM trajectory CSV (feet, 10 Hz, Lane_ID 1 = left-most) of vehicles 1-6."""
    rows = []
    for vehicle in (v for v in SIZES if v not in drop and v != 7):
        length, width = SIZES[vehicle]
        frames, t = _times(vehicle, 10.0)
        s, d, vs, vd = motion(vehicle, t)
        lane = np.floor(d / LANE_M).astype(int)
        for k in range(frames.shape[0]):
            rows.append({"Vehicle_ID": vehicle, "Frame_ID": frames[k], "Total_Frames": frames.shape[0],
                         "Global_Time": 1113433136100 + 100 * frames[k],
                         "Local_X": f"{(3 * 12.0) - d[k] / FOOT_M:.6f}",
                         "Local_Y": f"{(s[k] + length / 2) / FOOT_M:.6f}",
                         "v_Length": f"{length / FOOT_M:.6f}", "v_Width": f"{width / FOOT_M:.6f}",
                         "v_Class": 3 if vehicle in TRUCKS else 2,
                         "v_Vel": f"{math.hypot(vs[k], vd[k]) / FOOT_M:.6f}", "Lane_ID": 3 - lane[k]})
    return _write(folder / name, NGSIM, rows)


def edit_cell(path: Path, line: int, column: str, value: str) -> None:
    """Replace one cell (file line numbers, header = 1)."""
    text = path.read_text().splitlines()
    header = text[0].split(",")
    cells = text[line - 1].split(",")
    cells[header.index(column)] = value
    text[line - 1] = ",".join(cells)
    path.write_text("\n".join(text) + "\n")


def drop_column(path: Path, column: str) -> None:
    rows = [line.split(",") for line in path.read_text().splitlines()]
    i = rows[0].index(column)
    path.write_text("\n".join(",".join(r[:i] + r[i + 1:]) for r in rows) + "\n")
