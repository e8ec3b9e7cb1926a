"""NGSIM US-101 and I-80 vehicle trajectories as scenes.

The trajectory CSV (one row per vehicle and frame, 10 Hz, US customary units), with the columns of
the NGSIM data dictionary: `Vehicle_ID`, `Frame_ID` (tenths of a second), `Total_Frames`,
`Global_Time` [ms], `Local_X` (lateral position of the front centre of the vehicle from the
left-most edge of the section, in the direction of travel [ft]), `Local_Y` (longitudinal position
of the front centre from the entry edge of the section [ft]), `Global_X`, `Global_Y` [ft],
`v_Length`, `v_Width` [ft], `v_Class` (1 motorcycle, 2 car, 3 truck), `v_Vel` [ft/s],
`v_Acc` [ft/s^2], `Lane_ID` (1 = left-most lane), `Preceding`, `Following`, `Space_Headway`
[ft], `Time_Headway` [s]. Later exports add columns (e.g. `Location`); they are ignored. Read:
Vehicle_ID, Frame_ID, Local_X, Local_Y, v_Length, v_Width, v_Class, v_Vel, Lane_ID.

Conversion (see _recorded.py for the rest): 1 ft = 0.3048 m. The carriageway is taken to have
n = the largest Lane_ID in the file lanes of 12 ft (NGSIM US-101's, configs/roads/us101.toml), its right
edge at n 12 ft from the left edge: s = Local_Y - v_Length / 2 (the centre, not the front),
d = n 12 ft - Local_X. The lane index (0 = rightmost) is n - Lane_ID, and lane changes are read
from Lane_ID. `v_Vel` is the total speed; the speed along the road is v_Vel cos(heading). Frame f
is at t = f / 10 s. A file whose lanes lie less than 8 apart in Local_X is in metres and refused,
and the motion must be plausible (_recorded_checks.py). Motorcycles become CAR (there is no
motorcycle kind), trucks TRUCK.
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

FOOT_M = 0.3048
LANE_WIDTH_FT = 12.0
FRAME_RATE_HZ = 10.0
MIN_LANE_SPACING_FT = 8.0  # between a lane of metres (3.7) and one of feet (12)
_COLUMNS = ("Vehicle_ID", "Frame_ID", "Local_X", "Local_Y", "v_Length", "v_Width", "v_Class", "v_Vel", "Lane_ID")
_KINDS = {1: CAR, 2: CAR, 3: TRUCK}


def _check(path: Path, cols: dict[str, np.ndarray], lines: np.ndarray) -> None:
    for name, ok, what in (
        ("v_Length", cols["v_Length"] > 0, "> 0 ft"),
        ("v_Width", cols["v_Width"] > 0, "> 0 ft"),
        ("v_Class", np.isin(cols["v_Class"], list(_KINDS)), "1, 2 or 3"),
        ("Lane_ID", cols["Lane_ID"] >= 1, "a lane number >= 1"),
    ):
        if not np.all(ok):
            bad = int(np.argmin(ok))
            raise InputError(f"{path}, line {lines[bad]}: column {name!r} must be {what}, got {cols[name][bad]:g}")


def _check_feet(path: Path, cols: dict[str, np.ndarray], lane_id: np.ndarray) -> None:
    """Refuse a file in metres: its lanes' median Local_X lie about 12 apart in feet, 3.7 in metres."""
    lanes = [lane for lane in np.unique(lane_id) if (lane_id == lane).sum() >= 10]
    if len(lanes) < 2:
        return
    centres = np.array([np.median(cols["Local_X"][lane_id == lane]) for lane in lanes])
    spacing = float(np.median(np.diff(centres) / np.diff(lanes)))
    if spacing < MIN_LANE_SPACING_FT:
        raise InputError(f"{path}: its lanes' centres lie {spacing:.3g} apart in Local_X, a lane in metres; NGSIM "
                         f"is in feet ({LANE_WIDTH_FT:g} ft lanes): convert Local_X, Local_Y, v_Length, v_Width "
                         "and v_Vel to feet")


def read_ngsim(csv_path: str | Path) -> Recording:
    """The tracks of an NGSIM trajectory file in SI and the road frame (module doc)."""
    path = Path(csv_path)
    cols, lines = read_columns(path, _COLUMNS)
    _check(path, cols, lines)
    ids = integers(path, "Vehicle_ID", cols["Vehicle_ID"], lines)
    frame = integers(path, "Frame_ID", cols["Frame_ID"], lines)
    lane_id = integers(path, "Lane_ID", cols["Lane_ID"], lines)
    num_lanes = int(lane_id.max())
    length, width = cols["v_Length"] * FOOT_M, cols["v_Width"] * FOOT_M
    s = cols["Local_Y"] * FOOT_M - 0.5 * length
    d = (num_lanes * LANE_WIDTH_FT - cols["Local_X"]) * FOOT_M
    speed = cols["v_Vel"] * FOOT_M
    _check_feet(path, cols, lane_id)
    check_sizes(path, length, width, lines, ("v_Length", "v_Width"))
    check_speeds(path, speed, lines)
    check_motion(path, ids, frame, s, d, speed, FRAME_RATE_HZ, lines, "the NGSIM frame rate")
    check_road(path, d, num_lanes * LANE_WIDTH_FT * FOOT_M, lines)
    tracks = []
    for rows in group_rows(ids, frame):
        first = rows[0]
        tracks.append(Track(
            vehicle_id=int(ids[first]), frame=frame[rows], s_m=s[rows], d_m=d[rows], speed_mps=speed[rows],
            lane=num_lanes - lane_id[rows], lane_id=lane_id[rows], length_m=float(length[first]),
            width_m=float(width[first]), kind=_KINDS[int(cols["v_Class"][first])], carriageway=0,
        ))
    return Recording(path=str(path), frame_rate_hz=FRAME_RATE_HZ, tracks=tuple(tracks), speed_is_total=True)


def load_ngsim(
    csv_path: str | Path, *, window_s: float = DEFAULT_WINDOW_S, crossing_at_s: float | None = None,
    hold_s: float = DEFAULT_HOLD_S, dtype=jnp.float32,
) -> list[Scene]:
    """One 10 Hz scene per usable lane change of an NGSIM US-101 / I-80 trajectory CSV.

    See _recorded.py for the windows, the ego and the roles.
    """
    check_window(window_s, crossing_at_s, hold_s)  # before reading a large file
    cut = recorded_scenes(read_ngsim(csv_path), window_s=window_s, crossing_at_s=crossing_at_s, hold_s=hold_s, dtype=dtype)
    return list(cut.scenes)
