"""The component benchmarks run on the current API (both once broke unnoticed when
`relevance_reach` gained its arguments): tiny sizes, checking each prints its table."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _run(*args: str) -> str:
    out = subprocess.run([sys.executable, *args], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


@pytest.mark.slow
def test_bench_scene_runs():
    text = _run("benchmarks/bench_scene.py", "--variants", "2", "--repeats", "1", "--background", "10")
    assert "all six" in text and "relevant set of sc01" in text
    kept = [line.split() for line in text.splitlines() if line.strip().startswith(("0 ", "10 "))]
    assert [row[0] for row in kept] == ["0", "10"] and int(kept[1][1]) == int(kept[0][1]) + 10


@pytest.mark.slow
def test_bench_sensor_runs():
    text = _run("benchmarks/bench_sensor.py", "--variants", "2", "--repeats", "1")
    rows = [line for line in text.splitlines() if line.startswith(("radar ", "camera "))]
    assert len(rows) == 12 and all(row.split()[-1] in ("ok", "MISSED") for row in rows), text


@pytest.mark.slow
def test_bench_detection_runs_a_suite():
    # The suite (radar + camera under their probabilistic laws, r the radar's HFOV): E_ref with
    # its standard error and the estimators beside it, one point, 2 draws.
    text = _run("benchmarks/bench_detection.py", "--sensor", "suite", "--points", "20", "--draws", "2",
                "--mc-samples", "0")
    row = next(line for line in text.splitlines() if line.startswith("r   20.00"))
    assert "E_ref" in row and "mean_field" in row and "relaxed_reference" in row, text


@pytest.mark.slow
def test_bench_relaxation_times_each_estimator():
    text = _run("benchmarks/bench_relaxation.py", "--cost-at", "20", "--repeats", "1", "--draws", "2")
    rows = {line.split("|")[1].strip(): line for line in text.splitlines() if line.startswith("| ")}
    for program in ("E_ref", "relaxed-reference value", "straight-through value+grad"):
        assert program in rows, text
    assert rows["E_ref"].split("|")[3].strip() == "1.00"


@pytest.mark.slow
def test_bench_relaxation_judges_a_solve_on_fresh_draws(tmp_path):
    # One tiny solve (2 draws, a 3-deg interval) judged on 2 fresh draws, with Brent beside it:
    # on E_ref's own draws the judge's paired gap is the solve's reported gap to the grid's best.
    import json

    out = tmp_path / "judge.json"
    _run("benchmarks/bench_relaxation.py", "--estimator", "straight-through", "--draws", "2", "--solve", "20:23",
         "--judge-draws", "2", "--judge-grid", "--brent", "--json", str(out))
    row = json.loads(out.read_text())["solve"][0]
    judge = row["judge"]
    assert judge["fresh_draws"] == 2 and judge["r_best"] in (20.0, 21.0, 22.0, 23.0)
    assert judge["fresh_grid_best_r"] in (20.0, 21.0, 22.0, 23.0)
    assert judge["own"]["rel"] == pytest.approx(row["rel_to_grid_best"], abs=1e-12)
    assert row["brent"]["brent_evaluations"] >= 1


@pytest.mark.slow
def test_bench_intervals_runs_and_renders_its_table(tmp_path):
    # One scenario, 1 and 2 variants, one seed: a row without an interval and a row with one,
    # the JSON's numbers in the table rendered into a page's block.
    import json

    out, page = tmp_path / "intervals.json", tmp_path / "page.md"
    page.write_text("before\n<!-- intervals-table -->\nstale rows\n<!-- /intervals-table -->\nafter\n")
    _run("benchmarks/bench_intervals.py", "--variants", "1,2", "--seeds", "0", "--scenarios", "sc05",
         "--json", str(out), "--render", str(page))
    (prob,) = json.loads(out.read_text())["problems"]
    one, two = prob["rows"]
    assert (one["variants"], one["E_half_m"], one["with_interval"]) == (1, None, 0)
    assert two["variants"] == 2 and two["E_half_m"] > 0 and two["with_interval"] == 1
    text = page.read_text()
    assert text.startswith("before\n") and text.endswith("after\n") and "stale rows" not in text
    assert f"| 2 | {two['wall_s']:.0f} | {two['E_m']:.2f} | {two['E_half_m']:.2f} |" in text
