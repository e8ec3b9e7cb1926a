"""Plausibility of a recording's motion, checked as it is read: one clear refusal naming the file
and the line, before anything is computed from numbers that cannot be right.

- Frame rate. Between consecutive frames of a vehicle, the distance moved over the time the frame
  rate gives must match the recorded speed: the median ratio of the two over every vehicle
  moving faster than 1 m/s must lie in [0.8, 1.25]. A mislabelled rate (25 Hz data labelled
  10 Hz moves 2.5 times its speed) fails it, and the message names the rate that would fit.
- Glitches. A vehicle may not move more than GLITCH_M_S (20 m/s) plus half its recorded speed
  faster than that speed between two frames, along or across the road: a position glitch of a
  metre at 25 Hz is 25 m/s.
- Speeds within SPEED_RANGE_MPS ([-5, 90] m/s along the direction of travel: 324 km/h).
- The road. A vehicle centre lies within ROAD_MARGIN_M (3.5 m, a hard shoulder) outside the
  recording's outermost lane markings.
- Sizes. A vehicle is at most MAX_LENGTH_M (30 m: a long road train) long and MAX_WIDTH_M (5 m: a
  wide load) wide.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from diffsense.runtime import InputError

RATE_RATIO_RANGE = (0.8, 1.25)
GLITCH_M_S = 20.0
SPEED_RANGE_MPS = (-5.0, 90.0)
ROAD_MARGIN_M = 3.5
_MOVING_MPS = 1.0
MAX_LENGTH_M = 30.0
MAX_WIDTH_M = 5.0


def check_sizes(path: Path, length_m: np.ndarray, width_m: np.ndarray, lines: np.ndarray,
                columns: tuple[str, str]) -> None:
    """Every vehicle's length within (0, MAX_LENGTH_M] and width within (0, MAX_WIDTH_M] [m];
    `columns` names the file's (length, width) columns."""
    for what, column, size, most in (("length", columns[0], length_m, MAX_LENGTH_M),
                                     ("width", columns[1], width_m, MAX_WIDTH_M)):
        bad_rows = ~((size > 0.0) & (size <= most))
        if bad_rows.any():
            bad = int(np.argmax(bad_rows))
            raise InputError(f"{path}, line {lines[bad]}: column {column!r}, the vehicle's {what}, must be in the "
                             f"plausible (0, {most:g}] m, got {float(size[bad])} m")


def check_road(path: Path, d_m: np.ndarray, width_m: np.ndarray | float, lines: np.ndarray) -> None:
    """Every centre within ROAD_MARGIN_M of the road [0, width] (d from the right edge) [m]."""
    outside = (d_m < -ROAD_MARGIN_M) | (d_m > width_m + ROAD_MARGIN_M) | ~np.isfinite(d_m)
    if outside.any():
        bad = int(np.argmax(outside))
        width = float(np.broadcast_to(width_m, d_m.shape)[bad])
        raise InputError(f"{path}, line {lines[bad]}: a vehicle centre {d_m[bad]:.6g} m from the carriageway's "
                         f"right edge is off its road (lane markings span 0 to {width:.4g} m; at most "
                         f"{ROAD_MARGIN_M:g} m beyond them)")


def check_speeds(path: Path, speed_mps: np.ndarray, lines: np.ndarray) -> None:
    lo, hi = SPEED_RANGE_MPS
    bad_rows = ~((speed_mps >= lo) & (speed_mps <= hi))
    if bad_rows.any():
        bad = int(np.argmax(bad_rows))
        raise InputError(f"{path}, line {lines[bad]}: a speed of {speed_mps[bad]:.6g} m/s along the direction of "
                         f"travel is outside the plausible [{lo:g}, {hi:g}] m/s")


def check_motion(path: Path, ids: np.ndarray, frame: np.ndarray, s_m: np.ndarray, d_m: np.ndarray,
                 speed_mps: np.ndarray, rate_hz: float, lines: np.ndarray, rate_name: str) -> None:
    """The frame rate against positions and speeds, then position glitches (module doc). s, d and
    the speed are the file's own (before any shift by a file-wide extreme, which one glitch would move)."""
    order = np.lexsort((frame, ids))  # stable: of rows repeating a (vehicle, frame), the first is read
    repeat = np.zeros(order.shape, bool)
    repeat[1:] = (ids[order][1:] == ids[order][:-1]) & (frame[order][1:] == frame[order][:-1])
    order = order[~repeat]
    same = ids[order][1:] == ids[order][:-1]
    a, b = order[:-1][same], order[1:][same]
    if a.shape[0] == 0:
        return
    dt = (frame[b] - frame[a]) / rate_hz
    with np.errstate(all="ignore"):
        moved = (s_m[b] - s_m[a]) / dt
        across = (d_m[b] - d_m[a]) / dt
    speed = 0.5 * (speed_mps[a] + speed_mps[b])
    moving = np.abs(speed) > _MOVING_MPS
    if moving.sum() >= 10:
        with np.errstate(all="ignore"):
            ratio = float(np.median(moved[moving] / speed[moving]))
        lo, hi = RATE_RATIO_RANGE
        if not lo <= ratio <= hi:
            with np.errstate(all="ignore"):
                fitting = rate_hz / ratio  # at the true rate the distance moved is the speed
            fits = f"; {fitting:.4g} Hz would fit" if np.isfinite(fitting) and fitting > 0 else ""
            raise InputError(f"{path}: {rate_name} = {rate_hz:g} Hz contradicts the positions and speeds: at that "
                             f"rate vehicles move {ratio:.3g} times their recorded speed{fits}")
    limit = GLITCH_M_S + 0.5 * np.abs(speed)
    jump = ~((np.abs(moved - speed) <= limit) & (np.abs(across) <= limit))
    if jump.any():
        k = int(np.argmax(jump))
        raise InputError(f"{path}, lines {lines[a[k]]} to {lines[b[k]]}: vehicle {ids[a[k]]} moves "
                         f"{np.hypot(s_m[b[k]] - s_m[a[k]], d_m[b[k]] - d_m[a[k]]):.6g} m in {dt[k]:.3g} s at a "
                         f"recorded speed of {speed[k]:.4g} m/s: a position glitch")
