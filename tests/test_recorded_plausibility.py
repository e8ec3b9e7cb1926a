"""Recordings whose numbers cannot be right are refused as they are read, in one line naming the
file (and the line where one is to blame): a frame rate the positions and speeds contradict,
position glitches, implausible speeds, centres off the road, NGSIM in metres, ids past exact
integers. The generated highD-shaped recording and the shared small files pass every check."""

from __future__ import annotations

import csv
import subprocess
import sys
import time

import _recorded_files as files
import numpy as np
import pytest

from diffsense.runtime import InputError
from diffsense.scene import read_highd, read_ngsim
from tests._highd_like import write_highd_like


def _refused(call, *culprits) -> str:
    with pytest.raises(InputError) as e:
        call()
    message = str(e.value)
    assert "\n" not in message and all(str(c) in message for c in culprits), message
    return message


@pytest.fixture
def highd_like(tmp_path):
    return write_highd_like(tmp_path, duration_s=30.0)


def test_plausible_recordings_pass(highd_like, tmp_path):
    assert len(read_highd(highd_like).tracks) > 20
    assert len(read_ngsim(files.write_ngsim(tmp_path)).tracks) == 6


@pytest.mark.parametrize("rate, fits", [(10, "25"), (100, "25"), (1e-300, None)])
def test_a_frame_rate_the_motion_contradicts_is_refused_naming_the_rate_that_fits(highd_like, rate, fits):
    meta = highd_like.with_name("07_recordingMeta.csv")
    files.edit_cell(meta, 2, "frameRate", repr(rate))
    message = _refused(lambda: read_highd(highd_like), meta.name, "frameRate")
    if fits:
        assert f"{fits} Hz" in message


@pytest.mark.parametrize("column, value", [("x", "1e300"), ("x", "1e6"), ("y", "1e300"), ("y", "-40"),
                                           ("xVelocity", "200"), ("xVelocity", "nan")])
def test_a_glitch_an_implausible_speed_or_a_centre_off_the_road_names_its_line(highd_like, column, value):
    files.edit_cell(highd_like, 40, column, value)
    message = _refused(lambda: read_highd(highd_like), highd_like.name)
    assert "line" in message and "40" in message


def test_a_centre_on_the_hard_shoulder_is_accepted(tmp_path):
    # Vehicle 3 of the shared file, in the left-most lane, moved for good to 2.5 m beyond its marking.
    tracks = files.write_highd(tmp_path)
    rows = list(csv.reader(tracks.open()))
    header = rows[0]
    vid, y = header.index("id"), header.index("y")
    for row in rows[1:]:
        if row[vid] == "3":
            row[y] = f"{float(row[y]) - 0.5 * files.LANE_M - 2.5:.6f}"  # image y grows downwards, to the right
    with tracks.open("w", newline="") as handle:
        csv.writer(handle).writerows(rows)
    read_highd(tracks)


def test_ngsim_written_in_metres_is_refused(tmp_path):
    path = files.write_ngsim(tmp_path)
    rows = list(csv.reader(path.open()))
    header = rows[0]
    for row in rows[1:]:
        for name in ("Local_X", "Local_Y", "v_Length", "v_Width", "v_Vel"):
            row[header.index(name)] = f"{float(row[header.index(name)]) * files.FOOT_M:.6f}"
    with path.open("w", newline="") as handle:
        csv.writer(handle).writerows(rows)
    _refused(lambda: read_ngsim(path), path.name, "feet")


@pytest.mark.parametrize("value", ["1e19", "9007199254740993", "-1e300"])
def test_ids_past_exact_integers_are_refused(tmp_path, value):
    path = files.write_ngsim(tmp_path)
    files.edit_cell(path, 2, "Vehicle_ID", value)
    _refused(lambda: read_ngsim(path), path.name, "line 2", "Vehicle_ID")


def test_every_check_runs_before_any_array_is_made(tmp_path):
    # The checks read numpy columns only: a refusal never needs the JAX backend (reading the
    # shared files' tracks creates no jax.Array).
    rec = read_ngsim(files.write_ngsim(tmp_path))
    assert all(isinstance(t.s_m, np.ndarray) for t in rec.tracks)


def test_the_command_line_refuses_a_1e300_coordinate_at_once_writing_nothing(tmp_path):
    # Once the progress showed `E hard = nan m`, then a FloatingPointError traceback after ~15 s.
    tracks = files.write_highd(tmp_path)
    files.edit_cell(tracks, 7, "x", "1e300")
    out = tmp_path / "out"
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "diffsense.optimise", "--scenes", f"highd:{tracks}", "--out", str(out)],
                          capture_output=True, text=True, timeout=120)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), done.stderr[-2000:]
    assert tracks.name in lines[0] and "7" in lines[0]
    assert not out.exists() and time.perf_counter() - t0 < 60


@pytest.mark.parametrize("column, value", [("width", "40"), ("height", "6"), ("width", "1e39")])
def test_an_implausible_vehicle_size_is_refused(tmp_path, column, value):
    tracks = files.write_highd(tmp_path)
    meta = tracks.with_name("01_tracksMeta.csv")
    files.edit_cell(meta, 3, column, value)
    _refused(lambda: read_highd(tracks), meta.name, "line 3", repr(column))
