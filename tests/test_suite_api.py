"""Suites and many parameters through the public API and the CLI: qualified names, the box solve
end to end, and the bad inputs of a suite problem."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest

import diffsense as ds

ROOT = Path(__file__).resolve().parents[1]


def test_a_suite_problem_names_its_parameters_by_member():
    p = ds.Problem(sensor=["radar", "camera"], params={"radar.hfov": (20, 120), "camera.width": (640, 3840)})
    assert p.params == {"radar.hfov_deg": (20.0, 120.0), "camera.width_px": (640.0, 3840.0)}
    assert p.sensor_kind == "radar+camera"
    for params, match in [
        ({"hfov_deg": (20, 120)}, "qualified by the sensor"),
        ({"lidar.hfov_deg": (20, 120)}, "not in the suite"),
        ({"radar.width_px": (640, 1000)}, "unknown radar parameter 'width_px'"),
        ({"radar.hfov_deg": (120, 20)}, "lo < hi"),
        ({"camera.hfov_deg": (0, 30)}, "outside the domain"),
        ({"radar.hfov": (20, 60), "radar.hfov_deg": (20, 90)}, "named twice"),
    ]:
        with pytest.raises(ds.InputError, match=match):
            ds.Problem(sensor=["radar", "camera"], params=params)


@pytest.mark.slow
def test_a_suite_is_optimised_end_to_end():
    problem = ds.Problem(sensor=["radar", "camera"],
                         params={"radar.hfov_deg": (20.0, 120.0), "camera.hfov_deg": (30.0, 120.0)},
                         scenarios=["sc01"], variants=1, prediction_stride_frames=40,
                         predictor=ds.predictors.init_predictor(), box=ds.solve.BoxConfig(max_soft=12, starts=1))
    E = ds.objective(problem)
    grad = jax.grad(lambda r: E(r, tau=2.0))({"radar.hfov_deg": 50.0, "camera.hfov_deg": 60.0})
    assert set(grad) == {"radar.hfov_deg", "camera.hfov_deg"} and all(np.isfinite(float(v)) for v in grad.values())
    result = ds.optimise(problem, E=E)
    assert set(result.r_star) == set(problem.params)
    for name, (lo, hi) in problem.params.items():
        assert lo <= result.r_star[name] <= hi
    content = result.to_json()
    assert content["param"] is None and set(content["box"]["gradient"]) == set(problem.params)
    assert np.isfinite(content["E_hard_star"]) and content["by_scenario"]["sc01"]["E_hard"] == pytest.approx(
        content["E_hard_star"], rel=1e-9)


@pytest.mark.parametrize("args, needle", [
    (["--sensor", "radar,camera", "--param", "radar.bogus=1:2"], "unknown radar parameter 'bogus'"),
    (["--sensor", "radar,camera", "--param", "radar.hfov_deg=0:30"], "outside the domain"),
    (["--sensor", "radar,camera", "--param", "radar.hfov_deg=120:20"], "lo < hi"),
    (["--sensor", "radar,camera", "--param", "radar.hfov_deg=20:60", "--param", "radar.hfov=20:90"], "named twice"),
    (["--sensor", "radar,camera", "--param", "lidar.hfov_deg=20:60"], "not in the suite"),
])
def test_bad_suite_input_is_one_line_exit_2_nothing_written(tmp_path, args, needle):
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "diffsense.optimise", *args, "--out", str(out)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and needle in lines[0], proc.stderr
    assert not out.exists()
