"""Recorded traffic end to end: highD- and NGSIM-format files written here run the main job (one
parameter and a suite); what a Problem refuses of their names: tests/test_problem.py."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import diffsense as ds
from diffsense.scene import cut_recorded
from tests._highd_like import write_highd_like
from tests._recorded_files import write_highd, write_ngsim

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["highd", "ngsim"])
def test_the_main_job_runs_on_recorded_scenes(tmp_path, kind):
    path = write_highd(tmp_path) if kind == "highd" else write_ngsim(tmp_path)
    problem = ds.Problem(scenes=f"{kind}:{path}", params={"hfov_deg": (30.0, 180.0)}, steps=(30.0, 105.0, 180.0),
                         prediction_stride_frames=20, predictor=ds.predictors.init_predictor())
    result = ds.optimise(problem, figures=False)
    content = result.to_json()
    assert content["scenarios"] == [f"{path.name}#0"]
    assert 30.0 <= result.r_star["hfov_deg"] <= 180.0 and np.isfinite(result.E_hard_star)
    assert result.E_hard_star <= min(p.E_hard for p in result.sweep)


@pytest.mark.slow
def test_the_suite_optimiser_runs_on_recorded_scenes(tmp_path):
    # A radar+camera suite over a recording: the box solve, the fused tracks and the answer's
    # per-scene breakdown all take the recorded scene in place of a scenario.
    path = write_highd(tmp_path)
    problem = ds.Problem(scenes=f"highd:{path}", sensor=["radar", "camera"],
                         params={"radar.hfov_deg": (20.0, 120.0), "camera.hfov_deg": (30.0, 120.0)},
                         prediction_stride_frames=20, predictor=ds.predictors.init_predictor(),
                         box=ds.solve.BoxConfig(max_soft=8, starts=1))
    result = ds.optimise(problem, figures=False)
    content = result.to_json()
    assert content["scenarios"] == [f"{path.name}#0"]
    for name, (lo, hi) in problem.params.items():
        assert lo <= result.r_star[name] <= hi
    assert np.isfinite(result.E_hard_star)
    assert content["by_scenario"][f"{path.name}#0"]["E_hard"] == pytest.approx(result.E_hard_star, rel=1e-9)


@pytest.mark.slow
def test_the_command_line_runs_on_a_highd_shaped_recording_and_says_what_it_read(tmp_path):
    # The generated recording's lane changes (tests/_highd_like.py) as the main job's scenes: the
    # run reports the recording's summary and solves over every scene it kept.
    path = write_highd_like(tmp_path)
    summary = cut_recorded(f"highd:{path}").summary
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "diffsense.optimise", "--scenes", f"highd:{path}", "--param", "hfov",
                           "--interval", "30", "180", "--steps", "30,105,180", "--out", str(out)],
                          cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    assert summary.line() in done.stdout + done.stderr
    result = json.loads((out / "result.json").read_text())
    assert len(result["scenarios"]) == summary.scenes > summary.lane_changes / 2
    assert 30.0 <= result["r_star"]["hfov_deg"] <= 180.0
