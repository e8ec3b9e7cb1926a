"""Recorded windows that fit real recordings: on a generated highD-shaped recording (420 m at
25 Hz, vehicles in view 12-19 s) most lane changes become scenes, where the synthetic scenes'
20 s window keeps none; every window holds its target throughout and its crossing near a
prediction instant; what a vehicle does after the last instant changes no number."""

from __future__ import annotations

import csv
import subprocess
import sys

import jax.numpy as jnp
import numpy as np
import pytest

import diffsense as ds
from diffsense import scene as sc
from diffsense.runtime import InputError
from tests._highd_like import write_highd_like
from tests._recorded_files import write_highd

HISTORY_S, FUTURE_S = ds.predictors.CSLSTM_SPEC.history_s, ds.predictors.CSLSTM_SPEC.future_s


@pytest.fixture(scope="module")
def highd_like(tmp_path_factory):
    path = write_highd_like(tmp_path_factory.mktemp("highd_like"))
    return path, sc.read_highd(path)


def test_most_lane_changes_of_a_highd_shaped_recording_become_scenes(highd_like):
    path, rec = highd_like
    cut = sc.recorded_scenes(rec)
    summary = cut.summary
    assert summary.lane_changes >= 20 and {t.carriageway for t in rec.tracks} == {1, 2}
    assert summary.scenes > summary.lane_changes / 2
    assert summary.scenes + len(summary.dropped) == summary.lane_changes == len(cut.windows) + len(summary.dropped)
    assert {d.reason for d in summary.dropped} <= {"target_in_view", "no_ego"}
    ways = {rec.tracks[[t.vehicle_id for t in rec.tracks].index(w.vehicle_ids[1])].carriageway for w in cut.windows}
    assert ways == {1, 2}  # scenes from both driving directions
    with pytest.raises(InputError, match=str(path.name)):  # the synthetic scenes' 20 s window
        sc.recorded_scenes(rec, window_s=20.0, crossing_at_s=5.0)


def test_every_window_holds_its_target_and_its_crossing_near_an_instant(highd_like):
    _, rec = highd_like
    by_id = {t.vehicle_id: t for t in rec.tracks}
    cut = sc.recorded_scenes(rec, window_s=11.0, dtype=jnp.float64)
    for scene, window in zip(cut.scenes, cut.windows):
        assert scene.s_m.shape[0] == 111 and scene.role[:2].tolist() == [sc.EGO, sc.TARGET]
        target = by_id[window.vehicle_ids[1]]
        assert target.frame[0] / rec.frame_rate_hz <= window.start_s + 1e-9
        assert window.start_s + 11.0 <= target.frame[-1] / rec.frame_rate_hz + 1e-9
        into = window.crossing_s - window.start_s
        assert HISTORY_S - 2.0 - 1e-9 <= into <= 11.0 - FUTURE_S + 2.0 + 1e-9
        ego = by_id[window.vehicle_ids[0]]  # in view while the sensor looks
        assert ego.frame[0] / rec.frame_rate_hz <= window.start_s + 1e-9
        assert window.start_s + 11.0 - FUTURE_S <= ego.frame[-1] / rec.frame_rate_hz + 1e-9
    fixed = sc.recorded_scenes(rec, crossing_at_s=4.0)
    assert all(abs(w.crossing_s - w.start_s - 4.0) < 1e-9 for w in fixed.windows)
    assert fixed.summary.scenes <= cut.summary.scenes + len(cut.summary.dropped)


def _drop_rows(path, vehicle: int, after_frame: int) -> None:
    with path.open() as handle:
        rows = list(csv.reader(handle))
    header = rows[0]
    fid, vid = header.index("frame"), header.index("id")
    kept = [rows[0]] + [r for r in rows[1:] if not (int(r[vid]) == vehicle and int(r[fid]) > after_frame)]
    with path.open("w", newline="") as handle:
        csv.writer(handle).writerows(kept)


def test_a_vehicle_leaving_the_view_after_the_last_instant_changes_no_number(tmp_path):
    # The shared recording's one lane change (crossing at 10 s) in a 10 s window from 6 s: the
    # last prediction instant is at 11 s. The ego, which accelerates, is cut from the file just
    # after it: the scene continues it at its last speed, a motion the file never had.
    full, cut = tmp_path / "full", tmp_path / "cut"
    full.mkdir()
    cut.mkdir()
    _drop_rows(write_highd(cut), vehicle=2, after_frame=round(11.04 * 25))
    values = []
    for folder in (full, cut):
        path = write_highd(folder) if folder is full else folder / "01_tracks.csv"
        (scene,) = sc.load_highd(path, dtype=jnp.float64)
        values.append(scene)
        problem = ds.Problem(scenes=f"highd:{path}", predictor=ds.predictors.init_predictor(), prediction_stride_frames=5)
        E = ds.objective(problem)
        values.append([float(E({"hfov_deg": h}, mode="hard")) for h in (40.0, 120.0)])
    (whole, e_whole), (short, e_short) = values[:2], values[2:]
    assert not np.allclose(whole.s_m[-1, 0], short.s_m[-1, 0])  # the continuation is not the recording
    np.testing.assert_array_equal(whole.s_m[:51], short.s_m[:51])
    np.testing.assert_allclose(e_short, e_whole, rtol=1e-12)
    assert np.all(np.isfinite(e_whole))


@pytest.mark.parametrize("changes", [{"window_s": 7.9}, {"window_s": float("nan")}, {"crossing_at_s": 10.5},
                                      {"crossing_at_s": -1.0}])
def test_a_problem_refuses_windows_the_predictor_cannot_use(tmp_path, changes):
    path = write_highd(tmp_path)
    with pytest.raises(InputError, match=next(iter(changes))):
        ds.Problem(scenes=f"highd:{path}", **changes)


def test_window_settings_are_for_recorded_scenes_only(tmp_path):
    with pytest.raises(InputError, match="window_s"):
        ds.Problem(window_s=12.0)
    problem = ds.Problem(scenes=f"highd:{write_highd(tmp_path)}", window_s=12.0, crossing_at_s=3.0)
    assert (problem.traffic.window_s, problem.traffic.crossing_at_s) == (12.0, 3.0)
    assert ds.Problem(**problem.keywords()) == problem


@pytest.mark.parametrize("flags, culprit", [(["--window-s", "12"], "window_s"),
                                            (["--scenes", "highd:{path}", "--window-s", "5"], "window_s"),
                                            (["--scenes", "highd:{path}", "--crossing-at-s", "11"], "crossing_at_s")])
def test_the_command_line_refuses_window_flags_it_cannot_use(tmp_path, flags, culprit):
    path = write_highd(tmp_path)
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "diffsense.optimise", *[f.format(path=path) for f in flags],
                           "--out", str(out)], capture_output=True, text=True, timeout=120)
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: ") and culprit in lines[0], done.stderr
    assert not out.exists()
