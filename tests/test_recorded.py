"""Recorded traffic: highD and NGSIM files of the same motion load to the same scene.

The files are written by tests/_recorded_files.py from a closed-form motion; expected values below
are that motion evaluated by hand (s = s0 + v t ...), not the loaders' own formulas.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest

import _recorded_files as files
from diffsense.runtime._errors import InputError
from diffsense.scene import BACKGROUND, CAR, EGO, LEAD, TARGET, TARGET_LEAD, TRUCK, load_highd, load_ngsim, load_recorded
from diffsense.scene._highd import read_highd
from diffsense.scene._ngsim import read_ngsim
from diffsense.scene._recorded import group_rows, lane_changes, recorded_scenes


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    path = tmp_path_factory.mktemp("recorded")
    files.write_highd(path)
    files.write_ngsim(path)
    return path


@pytest.fixture(scope="module")
def loaded(folder):
    """(highD scene, highD info, NGSIM scene, NGSIM info) in float64."""
    (h,), (hi,) = recorded_scenes(read_highd(folder / "01_tracks.csv"), dtype=jnp.float64)
    (n,), (ni,) = recorded_scenes(read_ngsim(folder / "trajectories.csv"), dtype=jnp.float64)
    return h, hi, n, ni


def test_window_frames_and_roles(loaded):
    for scene, info in (loaded[:2], loaded[2:]):
        assert scene.dt_s == 0.1 and scene.s_m.shape == (201, 5)  # 20 s at 10 Hz
        assert (info.start_s, info.crossing_s) == (5.0, 10.0)
        # Ego 2 is in the lane the target changes into; decoy 3 (nearer, old lane) is background.
        assert info.vehicle_ids == (2, 1, 4, 5, 3)
        assert scene.role.tolist() == [EGO, TARGET, LEAD, TARGET_LEAD, BACKGROUND]
        assert scene.kind.tolist() == [CAR, CAR, TRUCK, CAR, CAR]
        assert bool(scene.present.all())


def test_units_and_road_frame(loaded):
    lane_m = 12 * 0.3048
    t = 5.0 + 0.1 * np.arange(201)
    for scene in (loaded[0], loaded[2]):
        np.testing.assert_allclose(scene.length_m, [4.8, 4.5, 12.0, 5.0, 4.2], atol=1e-5)
        np.testing.assert_allclose(scene.width_m, [1.9, 1.8, 2.5, 2.0, 1.7], atol=1e-5)
        np.testing.assert_allclose(scene.s_m[:, 0], 75 + 19 * t + 0.15 * t**2, atol=1e-3)  # ego centre
        np.testing.assert_allclose(scene.s_m[:, 1], 100 + 20 * t, atol=1e-3)
        np.testing.assert_allclose(scene.d_m[:, 0], 1.5 * lane_m, atol=1e-5)
        np.testing.assert_allclose(scene.d_m[0, 1], 2.5 * lane_m, atol=1e-5)
        np.testing.assert_allclose(scene.d_m[-1, 1], 1.5 * lane_m, atol=1e-5)
        np.testing.assert_allclose(scene.speed_mps[:, 0], 19 + 0.3 * t, atol=2e-3)
        np.testing.assert_array_equal(scene.x_m, scene.s_m)  # straight road, heading 0
        np.testing.assert_array_equal(scene.y_m, scene.d_m)
        assert float(jnp.abs(scene.road_angle_rad).max()) == 0.0
        # At t = 10 s, 0.03 s past mid-change, the target moves right at ~1.875 lane / 4 s: heading < 0.
        lateral = -1.875 * lane_m / 4.0
        np.testing.assert_allclose(scene.heading_rad[50, 1], math.atan2(lateral, 20.0), atol=2e-3)
        assert float(jnp.abs(scene.heading_rad[:, 0]).max()) < 1e-6


def test_lane_change_detected_at_the_crossing(loaded):
    for scene in (loaded[0], loaded[2]):
        assert scene.lane[:, 1].tolist() == [2] * 50 + [1] * 151  # first 10 Hz frame in lane 1: t = 10 s
        assert set(scene.lane[:, 0].tolist()) == {1}


def test_both_formats_give_the_same_scene(loaded):
    h, _, n, _ = loaded
    # Up to linear interpolation of 25 Hz (a h^2 / 8 < 0.3 mm here) and v_Vel cos(heading).
    for name, tol in (("s_m", 1e-3), ("d_m", 1e-3), ("x_m", 1e-3), ("y_m", 1e-3),
                      ("heading_rad", 1e-4), ("speed_mps", 1e-3), ("length_m", 1e-6), ("width_m", 1e-6)):
        np.testing.assert_allclose(getattr(h, name), getattr(n, name), atol=tol, err_msg=name)
    for name in ("lane", "kind", "role", "present"):
        np.testing.assert_array_equal(getattr(h, name), getattr(n, name), err_msg=name)


def test_highd_direction_one_is_mirrored(tmp_path, loaded):
    (m,), _ = recorded_scenes(read_highd(files.write_highd(tmp_path, direction=1)), dtype=jnp.float64)
    h = loaded[0]
    offset = m.s_m - h.s_m  # s is measured from another origin, and grows along travel in both
    np.testing.assert_allclose(offset, offset[0, 0], atol=1e-6)
    for name in ("d_m", "heading_rad", "speed_mps"):
        np.testing.assert_allclose(getattr(m, name), getattr(h, name), atol=1e-6, err_msg=name)
    np.testing.assert_array_equal(m.lane, h.lane)


def test_float32_default_and_dispatcher(folder):
    (h,) = load_highd(folder / "01_tracks.csv")
    assert h.s_m.dtype == jnp.float32 and h.lane.dtype == jnp.int32
    (n,) = load_recorded(f"ngsim:{folder / 'trajectories.csv'}")
    np.testing.assert_allclose(n.s_m, h.s_m, atol=2e-3)
    for spec in ("waymo:x.csv", "highd", "ngsim:"):
        with pytest.raises(InputError, match="highd:PATH"):
            load_recorded(spec)


def test_hysteresis():
    frame = np.arange(40)
    clean = np.array([3] * 20 + [2] * 20)
    assert lane_changes(clean, frame, 10) == [(20, 3, 2)]
    # A 0.4 s flicker is no change; the change happens at the run that holds.
    noisy = np.array([3] * 10 + [2] * 3 + [3] * 2 + [2] * 25)
    assert lane_changes(noisy, frame, 10) == [(15, 3, 2)]
    assert lane_changes(np.array(([3] * 4 + [2] * 4) * 5), frame, 10) == []
    assert lane_changes(np.array([3] * 20 + [1] * 20), frame, 10) == []  # not adjacent
    gap = np.concatenate([np.arange(20), np.arange(25, 45)])
    assert lane_changes(clean, gap, 10) == [(20, 3, 2)]


def test_duplicate_rows_keep_the_first():
    ids = np.array([5, 5, 2, 5, 2])
    frames = np.array([2, 1, 1, 1, 2])
    assert [g.tolist() for g in group_rows(ids, frames)] == [[2, 4], [1, 0]]


def test_ego_falls_back_to_the_original_lane(tmp_path):
    path = files.write_ngsim(tmp_path, drop=(2,))
    _, (info,) = recorded_scenes(read_ngsim(path))
    assert info.vehicle_ids[:2] == (3, 1)
    with pytest.raises(InputError, match="none with the target and an ego"):
        load_ngsim(files.write_ngsim(tmp_path, drop=(2, 3), name="noego.csv"))


def _one_line(excinfo, *parts):
    message = str(excinfo.value)
    assert "\n" not in message
    for part in parts:
        assert str(part) in message, (part, message)


def test_refusals_highd(tmp_path):
    tracks = files.write_highd(tmp_path)
    files.drop_column(tracks, "laneId")
    with pytest.raises(InputError) as e:
        load_highd(tracks)
    _one_line(e, tracks, "line 1", "laneId")
    tracks = files.write_highd(tmp_path)
    files.edit_cell(tracks, 7, "x", "12.5abc")
    with pytest.raises(InputError) as e:
        load_highd(tracks)
    _one_line(e, tracks, "line 7", "'x'", "12.5abc")
    meta = tmp_path / "01_recordingMeta.csv"
    files.edit_cell(meta, 2, "lowerLaneMarkings", "16.0")
    with pytest.raises(InputError) as e:
        load_highd(tracks)
    _one_line(e, meta, "line 2", "lowerLaneMarkings")
    meta.unlink()
    with pytest.raises(InputError) as e:
        load_highd(tracks)
    _one_line(e, tracks, "01_recordingMeta.csv")
    (tmp_path / "tracks.csv").write_text("frame\n1\n")
    with pytest.raises(InputError) as e:
        load_highd(tmp_path / "tracks.csv")
    _one_line(e, "NN_tracks.csv")


def test_refusals_ngsim(tmp_path):
    path = files.write_ngsim(tmp_path)
    files.drop_column(path, "Lane_ID")
    with pytest.raises(InputError) as e:
        load_ngsim(path)
    _one_line(e, path, "line 1", "Lane_ID")
    path = files.write_ngsim(tmp_path)
    files.edit_cell(path, 12, "Local_Y", "nan")
    with pytest.raises(InputError) as e:
        load_ngsim(path)
    _one_line(e, path, "line 12", "Local_Y")
    path = files.write_ngsim(tmp_path)
    files.edit_cell(path, 3, "v_Class", "7")
    with pytest.raises(InputError) as e:
        load_ngsim(path)
    _one_line(e, path, "line 3", "v_Class")
    with pytest.raises(InputError) as e:
        load_ngsim(files.write_ngsim(tmp_path, drop=(1,), name="straight.csv"))
    _one_line(e, "straight.csv", "no lane change found")
    with pytest.raises(InputError) as e:
        load_ngsim(tmp_path / "absent.csv")
    _one_line(e, "absent.csv", "no such file")
    with pytest.raises(InputError, match="duration_s"):
        load_ngsim(path, duration_s=5.0)


def test_blank_lines_are_skipped_and_counted(tmp_path, loaded):
    path = files.write_ngsim(tmp_path)
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:5] + [""] + lines[5:]) + "\n")  # numpy's reader is bypassed
    (scene,) = load_ngsim(path, dtype=jnp.float64)
    np.testing.assert_array_equal(scene.s_m, loaded[2].s_m)
    files.edit_cell(path, 12, "Local_X", "x")
    with pytest.raises(InputError) as e:
        load_ngsim(path)
    _one_line(e, path, "line 12", "Local_X")
