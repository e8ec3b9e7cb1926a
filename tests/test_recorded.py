"""Recorded traffic: highD and NGSIM files of the same motion load to the same scene; lane changes
by hysteresis; the window, ego and roles of recorded_scenes on hand-built tracks.

The files are written by tests/_recorded_files.py from a closed-form motion; expected values below
are that motion evaluated by hand (s = s0 + v t ...), not the loaders' own formulas.
"""

from __future__ import annotations

import math

import _recorded_files as files
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense import scene as sc
from diffsense.runtime import InputError


def cut(rec, window_s=20.0, crossing_at_s=5.0, **options):
    """(scenes, windows) of a recording, by default 20 s windows from 5 s before the crossing (the
    geometry the expected values below are written for)."""
    out = sc.recorded_scenes(rec, window_s=window_s, crossing_at_s=crossing_at_s, **options)
    return out.scenes, out.windows


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    path = tmp_path_factory.mktemp("recorded")
    files.write_highd(path)
    files.write_ngsim(path)
    return path


@pytest.fixture(scope="module")
def loaded(folder):
    """(highD scene, highD info, NGSIM scene, NGSIM info) in float64."""
    (h,), (hi,) = cut(sc.read_highd(folder / "01_tracks.csv"), dtype=jnp.float64)
    (n,), (ni,) = cut(sc.read_ngsim(folder / "trajectories.csv"), dtype=jnp.float64)
    return h, hi, n, ni


def test_window_frames_and_roles(loaded):
    for scene, info in (loaded[:2], loaded[2:]):
        assert scene.dt_s == 0.1 and scene.s_m.shape == (201, 5)  # 20 s at 10 Hz
        assert (info.start_s, info.crossing_s) == (5.0, 10.0)
        # Ego 2 is in the lane the target changes into; decoy 3 (nearer, old lane) is background.
        assert info.vehicle_ids == (2, 1, 4, 5, 3)
        assert scene.role.tolist() == [sc.EGO, sc.TARGET, sc.LEAD, sc.TARGET_LEAD, sc.BACKGROUND]
        assert scene.kind.tolist() == [sc.CAR, sc.CAR, sc.TRUCK, sc.CAR, sc.CAR]
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
    (m,), _ = cut(sc.read_highd(files.write_highd(tmp_path, direction=1)), dtype=jnp.float64)
    h = loaded[0]
    offset = m.s_m - h.s_m  # s is measured from another origin, and grows along travel in both
    np.testing.assert_allclose(offset, offset[0, 0], atol=1e-6)
    for name in ("d_m", "heading_rad", "speed_mps"):
        np.testing.assert_allclose(getattr(m, name), getattr(h, name), atol=1e-6, err_msg=name)
    np.testing.assert_array_equal(m.lane, h.lane)


def test_float32_default_and_dispatcher(folder):
    (h,) = sc.load_highd(folder / "01_tracks.csv", window_s=20.0, crossing_at_s=5.0)
    assert h.s_m.dtype == jnp.float32 and h.lane.dtype == jnp.int32
    (n,) = sc.load_recorded(f"ngsim:{folder / 'trajectories.csv'}", window_s=20.0, crossing_at_s=5.0)
    np.testing.assert_allclose(n.s_m, h.s_m, atol=2e-3)
    for spec in ("waymo:x.csv", "highd", "ngsim:"):
        with pytest.raises(InputError, match=repr(spec)):
            sc.load_recorded(spec)


def test_hysteresis():
    frame = np.arange(40)
    clean = np.array([3] * 20 + [2] * 20)
    assert sc.lane_changes(clean, frame, 10) == [(20, 3, 2)]
    # A 0.4 s flicker is no change; the change happens at the run that holds.
    noisy = np.array([3] * 10 + [2] * 3 + [3] * 2 + [2] * 25)
    assert sc.lane_changes(noisy, frame, 10) == [(15, 3, 2)]
    assert sc.lane_changes(np.array(([3] * 4 + [2] * 4) * 5), frame, 10) == []
    assert sc.lane_changes(np.array([3] * 20 + [1] * 20), frame, 10) == []  # not adjacent
    gap = np.concatenate([np.arange(20), np.arange(25, 45)])
    assert sc.lane_changes(clean, gap, 10) == [(20, 3, 2)]


def test_ego_falls_back_to_the_original_lane(tmp_path):
    path = files.write_ngsim(tmp_path, drop=(2,))
    _, (info,) = cut(sc.read_ngsim(path))
    assert info.vehicle_ids[:2] == (3, 1)
    with pytest.raises(InputError, match="noego.csv"):  # no lane change with an ego: no scene
        sc.load_ngsim(files.write_ngsim(tmp_path, drop=(2, 3), name="noego.csv"))


def test_the_loaders_refuse_in_one_line_naming_the_culprit(tmp_path):
    # (every reader's refusal: tests/test_recorded_readers.py)
    tracks = files.write_highd(tmp_path)
    files.edit_cell(tracks, 7, "x", "12.5abc")
    path = files.write_ngsim(tmp_path)
    for call, culprits in ((lambda: sc.load_highd(tracks), (tracks, "line 7", "'x'", "12.5abc")),
                           (lambda: sc.load_ngsim(files.write_ngsim(tmp_path, drop=(1,), name="straight.csv")),
                            ("straight.csv",)),  # no lane change found
                           (lambda: sc.load_ngsim(path, window_s=5.0), ("window_s",))):
        with pytest.raises(InputError) as e:
            call()
        assert "\n" not in str(e.value) and all(str(c) in str(e.value) for c in culprits), str(e.value)


def track(vehicle_id, frames, s0, lane_id, metres_per_frame=2.0):
    frame = np.asarray(frames)
    lane_id = np.asarray(lane_id)
    return sc.Track(vehicle_id=vehicle_id, frame=frame, s_m=s0 + metres_per_frame * frame, d_m=(3 - lane_id + 0.5) * 3.5,
                 speed_mps=np.full(frame.shape, 20.0), lane=3 - lane_id, lane_id=lane_id, length_m=4.5,
                 width_m=1.8, kind=sc.CAR, carriageway=0)


# 10 Hz. The target (id 1) crosses from lane id 2 to 1 at frame 50; the ego (id 2) drives behind
# it in lane id 1; id 3 is recorded exactly over the 8 s window from 2 s before the crossing
# (frames 30 to 110), id 4 leaves the view one frame early, after the window's one prediction
# instant (frame 60), id 5 enters one frame late.
FRAMES = np.arange(0, 121)
REC = sc.Recording(path="hand", frame_rate_hz=10.0, tracks=(
    track(1, FRAMES, 40.0, np.where(FRAMES < 50, 2, 1)),
    track(2, FRAMES, 10.0, np.ones_like(FRAMES)),
    track(3, np.arange(30, 111), 0.0, np.full(81, 2)),
    track(4, np.arange(30, 110), 60.0, np.full(80, 1)),
    track(5, np.arange(31, 111), 80.0, np.full(80, 1)),
))


def test_a_vehicle_leaving_the_view_after_the_last_instant_is_kept_and_one_entering_late_is_not():
    (scene,), (info,) = cut(REC, window_s=8.0, crossing_at_s=2.0, dtype=jnp.float64)
    assert info.vehicle_ids == (2, 1, 4, 3) and (info.start_s, info.crossing_s) == (3.0, 5.0)
    assert scene.s_m.shape == (81, 4)
    np.testing.assert_allclose(scene.s_m[:, 3], 2.0 * np.arange(30, 111), rtol=1e-15)
    # Past its last recorded frame, vehicle 4 goes on at its last speed (here its only one).
    np.testing.assert_allclose(scene.s_m[:, 2], 60.0 + 2.0 * np.arange(30, 111), rtol=1e-15)
    assert scene.lane[-1, 2] == scene.lane[0, 2]
    for name in ("d_m", "x_m", "y_m", "heading_rad", "road_angle_rad", "speed_mps", "lane"):
        assert getattr(scene, name).shape == (81, 4), name


def test_the_ego_is_strictly_behind_the_target_at_the_windows_first_frame():
    # Vehicle 5, in the lane the target enters, is abreast of it at the window's first frame
    # (frame 30, s = 100 m) and behind it from the next frame on (it drives 1 m a frame, not 2).
    rec = sc.Recording(path="hand", frame_rate_hz=10.0, tracks=(*REC.tracks, track(5, FRAMES, 70.0, np.ones_like(FRAMES), 1.0)))
    _, (info,) = cut(rec, window_s=8.0, crossing_at_s=2.0, dtype=jnp.float64)
    assert info.vehicle_ids[:2] == (2, 1)


def test_load_recorded_reads_either_prefix_in_any_case_and_a_colon_in_the_path(tmp_path):
    folder = tmp_path / "a:b"
    folder.mkdir()
    ngsim = files.write_ngsim(folder)
    highd = files.write_highd(folder)
    (by_ngsim,) = sc.load_recorded(f"NGSIM:{ngsim}")
    (by_highd,) = sc.load_recorded(f"HighD:{highd}")
    np.testing.assert_allclose(by_ngsim.s_m, by_highd.s_m, atol=2e-3)
