"""Recorded traffic's windows pinned on hand-built tracks: a vehicle recorded exactly over the
window is kept, the scene's arrays all have the window's shape, `cut_window` alone gives what
`recorded_scenes` gives, and `load_recorded` dispatches on its prefix (in any case, with a colon
in the path).
"""

from __future__ import annotations

import _recorded_files as files
import jax.numpy as jnp
import numpy as np

from diffsense.scene import CAR, load_recorded
from diffsense.scene._recorded import Recording, Track, cut_window, recorded_scenes


def track(vehicle_id, frames, s0, lane_id, metres_per_frame=2.0):
    frame = np.asarray(frames)
    lane_id = np.asarray(lane_id)
    return Track(vehicle_id=vehicle_id, frame=frame, s_m=s0 + metres_per_frame * frame, d_m=(3 - lane_id + 0.5) * 3.5,
                 speed_mps=np.full(frame.shape, 20.0), lane=3 - lane_id, lane_id=lane_id, length_m=4.5,
                 width_m=1.8, kind=CAR, carriageway=0)


# 10 Hz. The target (id 1) crosses from lane id 2 to 1 at frame 50; the ego (id 2) drives behind
# it in lane id 1; id 3 is recorded exactly over the 8 s window from 2 s before the crossing
# (frames 30 to 110), id 4 misses its last frame.
FRAMES = np.arange(0, 121)
REC = Recording(path="hand", frame_rate_hz=10.0, tracks=(
    track(1, FRAMES, 40.0, np.where(FRAMES < 50, 2, 1)),
    track(2, FRAMES, 10.0, np.ones_like(FRAMES)),
    track(3, np.arange(30, 111), 0.0, np.full(81, 2)),
    track(4, np.arange(30, 110), 60.0, np.full(80, 1)),
))


def test_a_vehicle_recorded_exactly_over_the_window_is_kept_and_one_frame_short_is_not():
    (scene,), (info,) = recorded_scenes(REC, duration_s=8.0, crossing_at_s=2.0, dtype=jnp.float64)
    assert info.vehicle_ids == (2, 1, 3) and (info.start_s, info.crossing_s) == (3.0, 5.0)
    assert scene.s_m.shape == (81, 3)
    np.testing.assert_allclose(scene.s_m[:, 2], 2.0 * np.arange(30, 111), rtol=1e-15)
    for name in ("d_m", "x_m", "y_m", "heading_rad", "road_angle_rad", "speed_mps", "lane"):
        assert getattr(scene, name).shape == (81, 3), name


def test_the_ego_is_strictly_behind_the_target_at_the_windows_first_frame():
    # Vehicle 5, in the lane the target enters, is abreast of it at the window's first frame
    # (frame 30, s = 100 m) and behind it from the next frame on (it drives 1 m a frame, not 2).
    rec = Recording(path="hand", frame_rate_hz=10.0, tracks=(*REC.tracks, track(5, FRAMES, 70.0, np.ones_like(FRAMES), 1.0)))
    _, (info,) = recorded_scenes(rec, duration_s=8.0, crossing_at_s=2.0, dtype=jnp.float64)
    assert info.vehicle_ids[:2] == (2, 1)


def test_cut_window_alone_gives_the_scene_recorded_scenes_gives():
    (want,), _ = recorded_scenes(REC, duration_s=8.0, crossing_at_s=2.0, dtype=jnp.float64)
    scene, info = cut_window(REC, 0, 50, 2, 1, 8.0, 2.0, jnp.float64)
    assert info.vehicle_ids == (2, 1, 3)
    for name in ("s_m", "d_m", "heading_rad", "speed_mps", "lane", "role"):
        np.testing.assert_array_equal(getattr(scene, name), getattr(want, name), err_msg=name)


def test_load_recorded_reads_either_prefix_in_any_case_and_a_colon_in_the_path(tmp_path):
    folder = tmp_path / "a:b"
    folder.mkdir()
    ngsim = files.write_ngsim(folder)
    highd = files.write_highd(folder)
    (by_ngsim,) = load_recorded(f"NGSIM:{ngsim}")
    (by_highd,) = load_recorded(f"HighD:{highd}")
    np.testing.assert_allclose(by_ngsim.s_m, by_highd.s_m, atol=2e-3)
