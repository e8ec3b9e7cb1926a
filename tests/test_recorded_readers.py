"""The NGSIM and highD readers on tiny hand-written files: each track's road-frame values worked
out by hand from the module docstrings' conversions; the CSV reading underneath (blank lines,
quoted cells, numbers only or not: the same tracks, and every refusal naming the file, the line
and the column).
"""

from __future__ import annotations

import _recorded_files as files
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.runtime import InputError
from diffsense.scene import CAR, TRUCK, load_highd, load_ngsim, read_highd, read_ngsim

FT = 0.3048
NGSIM_HEADER = "Vehicle_ID,Frame_ID,Total_Frames,Local_X,Local_Y,v_Length,v_Width,v_Class,v_Vel,Lane_ID,Location"
# Vehicle 3, a truck in Lane_ID 1 (the left-most of 3), two frames; vehicle 1, a motorcycle in
# Lane_ID 3 (the right-most). Rows out of order.
NGSIM_ROWS = ["3,11,2,6,101.5,15,6,3,50,1,us-101", "1,10,1,30,50,14,5.5,1,40,3,us-101",
              "3,10,2,6,100,15,6,3,49,1,us-101"]


def ngsim(tmp_path, rows=NGSIM_ROWS):
    path = tmp_path / "trajectories.csv"
    path.write_text("\n".join([NGSIM_HEADER, *rows]) + "\n")
    return path


def test_ngsim_tracks_in_si_and_the_road_frame(tmp_path):
    rec = read_ngsim(ngsim(tmp_path))
    assert rec.frame_rate_hz == 10.0 and rec.speed_is_total and rec.path == str(tmp_path / "trajectories.csv")
    one, three = rec.tracks
    # The carriageway is 3 x 12 ft; d from its right edge; s at the centre, half a length behind the front.
    assert (one.vehicle_id, one.kind, one.carriageway) == (1, CAR, 0)
    np.testing.assert_allclose(one.s_m, [(50 - 7) * FT], rtol=1e-15)
    np.testing.assert_allclose(one.d_m, [(36 - 30) * FT], rtol=1e-15)
    np.testing.assert_allclose(one.speed_mps, [40 * FT], rtol=1e-15)
    assert one.lane.tolist() == [0] and one.lane_id.tolist() == [3]
    assert (one.length_m, one.width_m) == pytest.approx((14 * FT, 5.5 * FT), rel=1e-15)
    assert (three.vehicle_id, three.kind) == (3, TRUCK)
    assert three.frame.tolist() == [10, 11]
    np.testing.assert_allclose(three.s_m, [92.5 * FT, 94 * FT], rtol=1e-15)
    np.testing.assert_allclose(three.d_m, [30 * FT, 30 * FT], rtol=1e-15)
    np.testing.assert_allclose(three.speed_mps, [49 * FT, 50 * FT], rtol=1e-15)
    assert three.lane.tolist() == [2, 2] and three.lane_id.tolist() == [1, 1]


def refused(call, *culprits):
    with pytest.raises(InputError) as e:
        call()
    assert "\n" not in str(e.value) and all(str(c) in str(e.value) for c in culprits), str(e.value)


@pytest.mark.parametrize(("row", "column", "value"), [
    ("1,10,1,30,50,0,5.5,1,40,3,x", "v_Length", "0"), ("1,10,1,30,50,14,-1,1,40,3,x", "v_Width", "-1"),
    ("1,10,1,30,50,14,5.5,4,40,3,x", "v_Class", "4"), ("1,10,1,30,50,14,5.5,2,40,0,x", "Lane_ID", "0"),
    ("1.5,10,1,30,50,14,5.5,2,40,3,x", "Vehicle_ID", "1.5"), ("1,10.5,1,30,50,14,5.5,2,40,3,x", "Frame_ID", "10.5"),
    ("1,10,1,30,50,14,5.5,2,40,2.5,x", "Lane_ID", "2.5"),
])
def test_ngsim_refusals_name_the_line_the_column_and_the_value(tmp_path, row, column, value):
    path = ngsim(tmp_path, [NGSIM_ROWS[0], row, NGSIM_ROWS[2]])
    refused(lambda: read_ngsim(path), f"{path}, line 3: ", f"'{column}'", value)



# highD: markings at image y 2, 5.5, 9 (upper carriageway) and 13, 16.5, 20 (lower), 3.5 m lanes.
RECORDING = "id,frameRate,upperLaneMarkings,lowerLaneMarkings\n1,25,{upper},{lower}\n"
META = "id,width,height,initialFrame,class,drivingDirection\n1,4.5,2,1,Car,2\n2,12,2.5,1,{truck},{direction}\n"
# Vehicle 1 drives right (+x) in the lower lanes; vehicle 2, a truck, left (-x) in the upper ones.
TRACKS = "frame,id,x,y,xVelocity,laneId\n1,1,100,17,30,6\n2,1,101.2,17.1,30,6\n1,2,200,5.2,-25,2\n2,2,199,5.3,-25,3\n"


def highd(tmp_path, upper="2;5.5;9", lower="13;16.5;20", truck="Truck", direction="1", tracks=TRACKS, rate="25",
          meta=META):
    (tmp_path / "01_recordingMeta.csv").write_text(RECORDING.format(upper=upper, lower=lower).replace(",25,", f",{rate},"))
    (tmp_path / "01_tracksMeta.csv").write_text(meta.format(truck=truck, direction=direction))
    path = tmp_path / "01_tracks.csv"
    path.write_text(tracks)
    return path


def test_highd_tracks_in_each_carriageways_road_frame(tmp_path):
    rec = read_highd(highd(tmp_path))
    assert rec.frame_rate_hz == 25.0 and not rec.speed_is_total
    car, truck = rec.tracks
    # Lower lanes, driving +x: centre (x + 2.25, y + 1); s = x_c, d = 20 - y_c from the bottom marking.
    assert (car.vehicle_id, car.kind, car.carriageway) == (1, CAR, 2)
    np.testing.assert_allclose(car.s_m, [102.25, 103.45], rtol=1e-15)
    np.testing.assert_allclose(car.d_m, [2.0, 1.9], rtol=1e-14)
    np.testing.assert_allclose(car.speed_mps, [30.0, 30.0])
    assert car.lane.tolist() == [0, 0] and car.lane_id.tolist() == [6, 6]
    assert (car.length_m, car.width_m) == (4.5, 2.0)
    # Upper lanes, driving -x, mirrored: s = x_ref - x_c with x_ref = 200 + 12 (the largest
    # x + length in the file), d = y_c - 2 from the top marking; speed = -xVelocity.
    assert (truck.vehicle_id, truck.kind, truck.carriageway) == (2, TRUCK, 1)
    np.testing.assert_allclose(truck.s_m, [212 - 206.0, 212 - 205.0], rtol=1e-14)
    np.testing.assert_allclose(truck.d_m, [6.45 - 2, 6.55 - 2], rtol=1e-14)
    np.testing.assert_allclose(truck.speed_mps, [25.0, 25.0])
    assert truck.lane.tolist() == [1, 1] and truck.lane_id.tolist() == [2, 3]


@pytest.mark.parametrize(("y", "lane"), [(17.0, 0), (15.51, 0), (15.5, 1), (15.49, 1), (12.0, 1), (9.5, 1),
                                         (20.5, 0)])
def test_highd_lanes_count_the_markings_between_the_right_edge_and_the_centre(tmp_path, y, lane):
    # Vehicle 1's centre at y_c = y + 1 against markings 13, 16.5, 20: d = 20 - y_c, lane 0 below
    # 3.5 m, lane 1 from the marking on; off the road the lane is clipped to the nearest one.
    tracks = f"frame,id,x,y,xVelocity,laneId\n1,1,100,{y},30,6\n1,2,200,5.2,-25,2\n"
    (car, _) = read_highd(highd(tmp_path, tracks=tracks)).tracks
    assert car.lane.tolist() == [lane]


@pytest.mark.parametrize(("edit", "where", "message"), [
    ({"upper": "5.5;2;9"}, "01_recordingMeta.csv, line 2",
     "column 'upperLaneMarkings' must be two or more ';'-separated numbers in increasing order, got '5.5;2;9'"),
    ({"lower": "13"}, "01_recordingMeta.csv, line 2",
     "column 'lowerLaneMarkings' must be two or more ';'-separated numbers in increasing order, got '13'"),
    ({"lower": "13;x"}, "01_recordingMeta.csv, line 2",
     "column 'lowerLaneMarkings' must be two or more ';'-separated numbers in increasing order, got '13;x'"),
    ({"lower": "13;13"}, "01_recordingMeta.csv, line 2",
     "column 'lowerLaneMarkings' must be two or more ';'-separated numbers in increasing order, got '13;13'"),
    ({"rate": "0"}, "01_recordingMeta.csv, line 2", "frameRate must be > 0, got 0.0"),
    ({"direction": "3"}, "01_tracksMeta.csv, line 3", "drivingDirection must be 1 or 2, got 3.0"),
    ({"truck": "Bus"}, "01_tracksMeta.csv, line 3", "class must be Car or Truck, got 'Bus'"),
    ({"meta": META.replace("\n2,12,", "\n2.5,12,")}, "01_tracksMeta.csv, line 3",
     "column 'id' must be a whole number, got 2.5"),
    ({"tracks": TRACKS + "3,9,1,1,1,1\n"}, "01_tracks.csv, line 6", "vehicle id 9 is not in 01_tracksMeta.csv"),
    ({"tracks": TRACKS + "3.5,1,1,1,1,1\n"}, "01_tracks.csv, line 6", "column 'frame' must be a whole number, got 3.5"),
    ({"tracks": TRACKS + "4,1,1,1,1,1.5\n"}, "01_tracks.csv, line 6", "column 'laneId' must be a whole number, got 1.5"),
])
def test_highd_refusals(tmp_path, edit, where, message):
    path = highd(tmp_path, **edit)
    culprit = message.split(" must ")[0].split(" is not ")[0]  # the column (or the vehicle id)
    refused(lambda: read_highd(path), f"{tmp_path / where.split(',')[0]},{where.split(',', 1)[1]}: ", culprit)


def test_highd_any_positive_frame_rate_is_read(tmp_path):
    assert read_highd(highd(tmp_path, rate="0.5")).frame_rate_hz == 0.5


def test_highd_files_are_found_by_name(tmp_path):
    path = highd(tmp_path)
    (tmp_path / "01_tracksMeta.csv").unlink()
    refused(lambda: read_highd(path), path, "01_tracksMeta.csv")
    other = tmp_path / "tracks01.csv"
    other.write_text(TRACKS)
    refused(lambda: read_highd(other), other, "NN_tracks.csv")
    refused(lambda: read_highd(tmp_path / "02_tracks.csv"), tmp_path / "02_tracks.csv")
    (tmp_path / "01_tracksMeta.csv").write_text("id,width,height,class,drivingDirection\n1,0,2,Car,2\n")
    refused(lambda: read_highd(path), f"{tmp_path / '01_tracksMeta.csv'}, line 2: ", "width", "0.0")


@pytest.mark.parametrize("kind", ["ngsim", "highd"])
def test_the_loaders_pass_every_window_option_on(tmp_path, kind):
    # The shared recording: the target holds its first lane for 10 s, then crosses at t = 10 s.
    load, path = (load_ngsim, files.write_ngsim(tmp_path)) if kind == "ngsim" else (load_highd, files.write_highd(tmp_path))
    with pytest.raises(InputError, match="a lane id held 12.0 s after another"):
        load(path, hold_s=12.0)
    (scene,) = load(path, window_s=10.0, crossing_at_s=2.0, dtype=jnp.float64)
    assert scene.s_m.shape == (101, 5) and scene.s_m.dtype == jnp.float64
    assert scene.lane[:, 1].tolist() == [2] * 20 + [1] * 81  # in the new lane from 2 s on


def test_numbers_only_blank_lines_or_no_last_newline_read_the_same_tracks(tmp_path):
    # numpy's reader for numbers only, the careful reader otherwise: one result either way
    want = read_ngsim(ngsim(tmp_path)).tracks
    text = "\n".join([NGSIM_HEADER, *NGSIM_ROWS])
    for variant in (text, text.replace("\n", "\n\n  ,  \n", 1) + "\n"):
        path = tmp_path / "variant.csv"
        path.write_text(variant)
        got = read_ngsim(path).tracks
        for a, b in zip(got, want, strict=True):
            assert a.vehicle_id == b.vehicle_id and np.array_equal(a.frame, b.frame)
            np.testing.assert_array_equal(a.s_m, b.s_m)
            np.testing.assert_array_equal(a.d_m, b.d_m)
    # after a blank line, a refusal names the file line the row is on (5, not 4)
    path = tmp_path / "blank.csv"
    path.write_text("\n".join([NGSIM_HEADER, NGSIM_ROWS[0], "", NGSIM_ROWS[1], NGSIM_ROWS[2].replace(",3,49,", ",4,49,")]))
    refused(lambda: read_ngsim(path), f"{path}, line 5: ", "'v_Class'")


def test_a_duplicated_row_keeps_the_first(tmp_path):
    rows = [NGSIM_ROWS[2], NGSIM_ROWS[2].replace(",100,", ",999,"), *NGSIM_ROWS[:2]]  # vehicle 3 at frame 10 twice
    three = read_ngsim(ngsim(tmp_path, rows)).tracks[1]
    assert three.frame.tolist() == [10, 11]
    np.testing.assert_allclose(three.s_m, [92.5 * FT, 94 * FT], rtol=1e-15)


def test_a_quoted_cell_over_two_lines_keeps_the_line_numbers(tmp_path):
    # tracksMeta with a note column the reader skips: vehicle 1's note spans lines 2-3, so vehicle 2
    # (an unknown class) is on line 4
    meta = ('id,width,height,initialFrame,class,drivingDirection,note\r\n1,4.5,2,1,Car,2,"two\r\nlines"\r\n'
            "2,12,2.5,1,Bus,1,one\r\n")
    path = highd(tmp_path)
    (tmp_path / "01_tracksMeta.csv").write_bytes(meta.encode())
    refused(lambda: read_highd(path), f"{tmp_path / '01_tracksMeta.csv'}, line 4: ", "Bus")


@pytest.mark.parametrize(("text", "culprits"), [
    ("", ()),  # empty: no header
    (NGSIM_HEADER.replace("Local_Y", "Local_Z") + "\n" + NGSIM_ROWS[0] + "\n", ("line 1", "'Local_Y'")),
    (NGSIM_HEADER + "\n", ()), (NGSIM_HEADER + "\n\n\n", ()),  # no data rows
    (NGSIM_HEADER + "\n" + NGSIM_ROWS[0] + "\n3,10,2\n", ("line 3", "'Lane_ID'")),  # too few cells
    (NGSIM_HEADER + "\n" + NGSIM_ROWS[0].replace("101.5", " 4x ") + "\n", ("line 2", "'Local_Y'", "'4x'")),
    (NGSIM_HEADER + "\n\n" + NGSIM_ROWS[0] + "\n" + NGSIM_ROWS[1].replace(",40,", ",-inf,") + "\n",
     ("line 4", "'v_Vel'", "-inf")),
    (NGSIM_HEADER + "\n" + NGSIM_ROWS[0].replace("101.5", "1e999") + "\n", ("line 2", "1e999")),
    (NGSIM_HEADER + "\n" + NGSIM_ROWS[0].replace("101.5", "2#3") + "\n", ("line 2", "2#3")),  # no comments
])
def test_a_bad_csv_is_refused_naming_the_file_line_and_column(tmp_path, text, culprits):
    path = tmp_path / "trajectories.csv"
    path.write_text(text)
    refused(lambda: read_ngsim(path), path, *culprits)
    refused(lambda: read_ngsim(tmp_path / "absent.csv"), tmp_path / "absent.csv")
