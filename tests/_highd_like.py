"""A generated recording shaped like highD: a 420 m stretch filmed at 25 Hz, three lanes each way,
vehicles in view 12-19 s, lane changes in both driving directions.

Each lane has its own speed (22, 28 and 34 m/s from the right, +-0.5 m/s per vehicle, so that
a vehicle is in view 420 / v = 12.4-19.5 s) and vehicles enter it every 2.5-4 s. About a third
change to an adjacent lane by a 4 s quintic whose crossing falls anywhere in their time in view
(at least 0.5 s from its ends). Positions are the highD layout's: bounding-box corner in image
coordinates, the upper carriageway driving towards -x. Deterministic in `seed`.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from tests._recorded_files import HIGHD_META, HIGHD_RECORDING, HIGHD_TRACKS

LENGTH_M = 420.0
RATE_HZ = 25.0
LANE_M = 3.75
LANE_SPEEDS_MPS = (22.0, 28.0, 34.0)  # right, middle, left
UPPER = [8.0 + i * LANE_M for i in range(4)]  # image y of the markings, top to bottom [m]
LOWER = [24.0 + i * LANE_M for i in range(4)]


def _vehicles(rng: np.random.Generator, duration_s: float) -> list[dict]:
    out = []
    for direction in (1, 2):
        for lane, speed in enumerate(LANE_SPEEDS_MPS):
            t = rng.uniform(0.0, 3.0)
            while t < duration_s:
                v = speed + rng.uniform(-0.5, 0.5)
                change = None
                if rng.uniform() < 0.35:
                    to = lane + (1 if lane == 0 else -1 if lane == 2 else rng.choice((-1, 1)))
                    change = (t + rng.uniform(0.5, LENGTH_M / v - 0.5), to)
                out.append(dict(direction=direction, lane=lane, speed=v, enter=t, change=change,
                                length=rng.uniform(4.0, 5.2), width=rng.uniform(1.7, 2.0)))
                t += rng.uniform(2.5, 4.0)
    return out


def _offset(vehicle: dict, t: np.ndarray) -> np.ndarray:
    """Lateral position of the centre from the carriageway's right edge [m]."""
    d = (vehicle["lane"] + 0.5) * LANE_M * np.ones_like(t)
    if vehicle["change"] is not None:
        crossing, to = vehicle["change"]
        u = np.clip((t - crossing + 2.0) / 4.0, 0.0, 1.0)  # the marking is crossed mid-manoeuvre
        d = d + (to - vehicle["lane"]) * LANE_M * (10 * u**3 - 15 * u**4 + 6 * u**5)
    return d


def write_highd_like(folder: Path, seed: int = 0, duration_s: float = 90.0, stem: str = "07") -> Path:
    """NN_tracks.csv and its two siblings in `folder`; returns the tracks file."""
    rng = np.random.default_rng(seed)
    tracks, meta = [], []
    for vid, vehicle in enumerate(_vehicles(rng, duration_s), start=1):
        first = int(np.ceil(vehicle["enter"] * RATE_HZ))
        last = min(int(np.floor((vehicle["enter"] + LENGTH_M / vehicle["speed"]) * RATE_HZ)), int(duration_s * RATE_HZ))
        frames = np.arange(first, last + 1)
        t = frames / RATE_HZ
        s = vehicle["speed"] * (t - vehicle["enter"])  # the centre, from the stretch's entry
        d = _offset(vehicle, t)
        lane = np.clip(np.floor(d / LANE_M).astype(int), 0, 2)
        length, width = vehicle["length"], vehicle["width"]
        if vehicle["direction"] == 2:  # towards +x, right edge at the bottom marking
            x_c, y_c, vx, lane_id = s, LOWER[-1] - d, vehicle["speed"], 8 - lane
        else:  # towards -x, right edge at the top marking
            x_c, y_c, vx, lane_id = LENGTH_M - s, UPPER[0] + d, -vehicle["speed"], 2 + lane
        for k in range(frames.shape[0]):
            tracks.append({"frame": frames[k], "id": vid, "x": f"{x_c[k] - length / 2:.3f}", "y": f"{y_c[k] - width / 2:.3f}",
                           "width": f"{length:.2f}", "height": f"{width:.2f}", "xVelocity": f"{vx:.3f}", "laneId": lane_id[k]})
        meta.append({"id": vid, "width": f"{length:.2f}", "height": f"{width:.2f}", "initialFrame": first,
                     "finalFrame": last, "numFrames": frames.shape[0], "class": "Car",
                     "drivingDirection": vehicle["direction"], "numLaneChanges": int(vehicle["change"] is not None)})
    recording = {"id": int(stem), "frameRate": int(RATE_HZ), "locationId": 2, "speedLimit": -1, "duration": duration_s,
                 "upperLaneMarkings": ";".join(f"{y:.2f}" for y in UPPER),
                 "lowerLaneMarkings": ";".join(f"{y:.2f}" for y in LOWER)}
    for name, header, rows in ((f"{stem}_tracksMeta.csv", HIGHD_META, meta),
                               (f"{stem}_recordingMeta.csv", HIGHD_RECORDING, [recording]),
                               (f"{stem}_tracks.csv", HIGHD_TRACKS, tracks)):
        with (folder / name).open("w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(header)
            writer.writerows([row.get(column, 0) for column in header] for row in rows)
    return folder / f"{stem}_tracks.csv"
