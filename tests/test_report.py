"""Report: result.json schema and atomic writing, figures, tables."""

from __future__ import annotations

import json
import math

import jax
import numpy as np
import pytest

from diffsense.runtime._io import write_json
from diffsense.study._result import RESULT_KEYS, Result
from diffsense.report import (
    comparison_table,
    plot_detection_timeline,
    plot_objective,
    plot_rmse_horizon,
    summary_table,
)
from diffsense.solve import SolveConfig, solve
from tests._analytic_objectives import HI, LO, bowl, staircase

DEG = 180.0 / math.pi


def _result(res, sensor, **changes):
    fields = dict(sensor=sensor, params={"hfov": (LO, HI)}, units={"hfov": "rad"}, r_star={"hfov": res.r_star},
                  E_hard_star=res.E_hard_star, E_soft_star=res.E_soft_star, solve=res,
                  programs_run={"solve": {"soft": 3, "hard": 2}, "figures": {"soft": 0, "hard": 0}},
                  wall_s={"compile": 1.5, "run": 0.25}, scenarios=("sc01",),
                  config={"solve": {"tau_schedule": [4.0, 2.0, 1.0]}, "seed": 0})
    return Result(**(fields | changes))


@pytest.fixture(scope="module")
def solved():
    """radar/camera stand-ins: two analytic objectives solved once."""
    pairs = {"radar": staircase(0.9), "camera": bowl(2.0)}
    return {s: solve(e2, eh, (LO, HI), config=SolveConfig()) for s, (e2, eh) in pairs.items()}


@pytest.fixture(scope="module")
def results(solved):
    return {s: _result(res, s).to_json() for s, res in solved.items()}


def _no_temp_files(folder):
    left = [p.name for p in folder.iterdir() if p.name.startswith(".") or p.suffix == ".tmp"]
    assert left == []


def test_result_json_has_every_key_and_is_valid(tmp_path, results):
    path = tmp_path / "out" / "result.json"
    write_json(path, results["radar"])
    data = json.loads(path.read_text())
    assert tuple(data) == RESULT_KEYS  # exactly the documented keys, in order (no dense check here)
    assert data["evaluations"]["objective"] + data["evaluations"]["gradient"] <= 20
    assert set(data["wall_s"]) == {"compile", "run"}
    assert all(set(p) == {"r", "E_hard", "E_soft"} for p in data["sweep"])
    assert data["E_hard_star"] <= min(p["E_hard"] for p in data["sweep"])
    assert {"python", "jax", "jaxlib", "flax", "optax", "optimistix", "numpy", "diffsense"} <= set(
        data["versions"]
    )
    assert data["versions"]["jax"] == jax.__version__
    _no_temp_files(path.parent)


def test_non_finite_numbers_become_null(solved):
    content = _result(solved["radar"], "radar", E_soft_star=float("nan")).to_json()
    assert content["E_soft_star"] is None
    json.dumps(content, allow_nan=False)


def test_dense_check_is_recorded_when_made(solved):
    content = _result(solved["radar"], "radar", dense_check={"step": 0.1}).to_json()
    assert content["dense_check"] == {"step": 0.1} and tuple(content)[:-1] == RESULT_KEYS


def test_figures_are_written_atomically(tmp_path, results):
    e2, eh = staircase(0.9)
    r = np.linspace(LO, HI, 61)
    e_soft = np.sqrt([float(e2(x, 1.0)) for x in r])
    e_hard = np.array([float(eh(x)) for x in r])
    de_dr = np.gradient(e_soft, r)
    res = results["radar"]
    plot_objective(
        tmp_path / "objective.png", r, e_soft, e_hard, de_dr, res["sweep"], res["r_star"]["hfov"],
        param="hfov", scale=DEG, unit="deg",
    )
    rng = np.random.default_rng(0)
    gt = np.linspace(0.1, 2.0, 25)
    steps = np.deg2rad([30.0, 60.0, 90.0])
    curves = {
        f"Sc-0{i}": {"gt": gt, "steps": {s: gt + rng.uniform(0, 1) for s in steps}}
        for i in range(1, 4)
    }
    plot_rmse_horizon(tmp_path / "rmse_horizon.png", curves, param="HFOV", scale=DEG, unit="deg")
    timeline = {s: rng.uniform(0, 1, size=(80, 3)) for s in np.deg2rad([30, 120])}
    roles = ["target", "lead", "left rear"]
    plot_detection_timeline(
        tmp_path / "detections.png", timeline, roles, param="HFOV", scale=DEG, unit="deg"
    )
    for name in ("objective.png", "rmse_horizon.png", "detections.png"):
        data = (tmp_path / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000
    _no_temp_files(tmp_path)
    with pytest.raises(ValueError, match="expected"):
        plot_detection_timeline(tmp_path / "bad.png", {1.0: np.ones((5, 2))}, ["target"])
    assert not (tmp_path / "bad.png").exists()
    _no_temp_files(tmp_path)


def test_summary_table_is_aligned_and_complete(results):
    text = summary_table(results["radar"], scale=DEG, unit="deg")
    lines = text.splitlines()
    assert lines[0].startswith("radar: hfov [deg] over [30, 180]")
    header, rows = lines[1], lines[3 : 3 + 6 + 1]
    end = header.index("E_soft [m]") + len("E_soft [m]")
    assert all(row[end - 1].isdigit() and row[end : end + 1] in ("", " ") for row in rows)
    assert sum("best step" in line for line in lines) == 1
    assert "r* " in text and "gradient evaluations" in text


def test_comparison_table_names_the_better_sensor(results):
    text = comparison_table(results, scale=DEG, unit="deg")
    assert "radar vs camera" in text.splitlines()[0]
    winner = min(results, key=lambda s: results[s]["E_hard_star"])
    assert text.splitlines()[-1].startswith(f"best: {winner}")
    other = dict(results["camera"], sweep=results["camera"]["sweep"][:-1])
    with pytest.raises(ValueError, match="other steps"):
        comparison_table({"radar": results["radar"], "camera": other})
