"""The case study's tables and statements (`diffsense case-study`) from a results file written by
hand: each table's numbers (to two decimals; each profile read with its own fill; the best step
every step within 1 cm of the least; a scenario flatter than 1 cm has none; the horizon's whole
seconds), the three statements' numbers, the page's sections, the figures written, and a missing
or malformed file refused by one line naming it."""

from __future__ import annotations

import json

import pytest
from test_report_tables import numbers

from diffsense.cli import case_study as command
from diffsense.cli import run
from diffsense.report import case_study

STEPS = [30.0, 60.0, 90.0]
HORIZON = [0.1 * (k + 1) for k in range(25)]  # RMSE at 0.2 .. 5 s: 0.1, 0.2, ..., 2.5 m


def _run(profile: str, sensor: str, fill: str, e: list[float], by: dict[str, list[float]]) -> dict:
    return {"weights": "ngsim", "profile": profile, "sensor": sensor, "fill": fill, "scenarios": list(by),
            "rmse_gt": [[h + i for h in HORIZON] for i in range(len(by))],
            "steps": [{"r": r, "E_hard": e[k], "tracked": {"E_tracked": e[k] / 2, "missed_share": 0.1 * k},
                       "by_scenario": {name: {"E_hard": v[k]} for name, v in by.items()},
                       "rmse_sensor": [[h + k for h in HORIZON] for _ in by]}
                      for k, r in enumerate(STEPS)]}


DATA = {
    "steps_deg": STEPS, "variants": 8, "machine": {"jax": "0.0.1", "backend": "cpu", "cpus": 2},
    "validation_rmse_m": {"ngsim": [0.5, 1.25, 2.0, 3.0, 4.5]},
    "runs": [
        _run("physical", "radar", "hold", [2.0, 1.5, 1.505], {"RLC": [2.0, 1.5, 1.5], "LLC": [1.0, 1.004, 1.002]}),
        _run("physical", "radar", "zero", [9.0, 9.0, 9.0], {"RLC": [9.0] * 3, "LLC": [9.0] * 3}),
        _run("physical", "camera", "hold", [3.0, 2.75, 2.5], {"RLC": [3.0, 2.75, 2.5], "LLC": [3.0, 2.75, 2.5]}),
        _run("paper", "radar", "zero", [4.0, 3.0, 2.0], {"RLC": [4.0, 3.0, 2.0], "LLC": [4.0, 3.0, 2.0]}),
        _run("paper", "camera", "zero", [1.0, 3.0, 3.5], {"RLC": [1.0, 3.0, 3.5], "LLC": [1.0, 3.0, 3.5]}),
    ],
}
RUNS = case_study.index_runs([DATA])


def _cells(table: str) -> list[list[str]]:
    """A markdown table's rows, cell by cell, the header and its rule left out."""
    return [[c.strip() for c in line.strip("|").split("|")] for line in table.splitlines()[2:]]


def test_the_pooled_table_reads_each_profile_with_its_own_fill():
    rows = _cells(case_study.pooled(RUNS, ["ngsim"], STEPS))
    assert [r[:4] for r in rows[::3]] == [["ngsim", "physical", "radar", "E_hard"], ["ngsim", "physical", "camera", "E_hard"],
                                          ["ngsim", "paper", "radar", "E_hard"], ["ngsim", "paper", "camera", "E_hard"]]
    assert [r[4:] for r in rows[:3]] == [["2.00", "1.50", "1.50", "60-90"], ["1.00", "0.75", "0.75", "60-90"],
                                         ["0.00", "0.10", "0.20", ""]]  # E_hard, E_tracked, missed share
    assert [r[-1] for r in rows[3::3]] == ["90", "90", "30"]  # camera (hold), radar and camera (paper, zero)


def test_a_scenario_flatter_than_a_centimetre_has_no_best_or_worst():
    rows = _cells(case_study.per_scenario(RUNS, STEPS))
    assert rows[:2] == [["ngsim", "physical", "radar", "RLC", "2.00", "1.50", "1.50", "60-90", "30"],
                        ["ngsim", "physical", "radar", "LLC", "1.00", "1.00", "1.00", "flat", ""]]
    assert len(rows) == 4 * 2 and rows[-1][-2:] == ["30", "90"]
    edge = case_study.index_runs([{"runs": [_run("paper", "camera", "zero", [0.0, 0.01, 0.005],
                                                  {"EDGE": [0.0, 0.01, 0.005]})]}])
    assert _cells(case_study.per_scenario(edge, STEPS))[0][-2:] == ["30-90", "60"]  # 1 cm: not flat


def test_the_imputation_and_ground_truth_tables():
    assert _cells(case_study.imputation(RUNS, STEPS)) == [
        ["ngsim", "physical", "hold", "2.00", "1.50", "1.50"], ["ngsim", "physical", "zero", "9.00", "9.00", "9.00"],
        ["ngsim", "paper", "zero", "4.00", "3.00", "2.00"]]
    assert _cells(case_study.ground_truth([DATA])) == [  # at 1, 2, 3, 4 and 5 s; then the model card's
        ["ngsim", "RLC", "0.50", "1.00", "1.50", "2.00", "2.50"], ["ngsim", "LLC", "1.50", "2.00", "2.50", "3.00", "3.50"],
        ["ngsim", "card / published", "0.50", "1.25", "2.00", "3.00", "4.50"]]


def test_the_three_statements():
    physical, paper = case_study.statements(RUNS, ["ngsim"], STEPS).splitlines()
    # (1) steps where radar is below camera; (2) radar's best steps, its E at 30 deg and best;
    # (3) camera's worst step and its spread above 30 deg.
    assert numbers(physical)[0] == [1, 3, 3, 2, 60, 30, 2.0, 1.5, 3, 30, 30, 0.25] and "60-90" in physical
    assert numbers(paper)[0] == [1, 1, 3, 2, 90, 30, 4.0, 2.0, 3, 90, 30, 0.5]


def test_the_page_prints_every_section_and_writes_the_figures(tmp_path, capsys):
    results = tmp_path / "r.json"
    results.write_text(json.dumps(DATA))
    assert case_study.print_case_study([str(results)], [str(tmp_path / "a=b")]) == 0
    out = capsys.readouterr().out
    assert numbers(out.splitlines()[0])[0] == [2, 8] and "0.0.1" in out  # jax 0.0.1, 2 cores, 8 variants
    assert len([line for line in out.splitlines() if line.startswith("### ")]) == 5
    assert case_study.statements(RUNS, ["ngsim"], STEPS) in out and case_study.pooled(RUNS, ["ngsim"], STEPS) in out
    figures = sorted(p.name for p in (tmp_path / "a=b").iterdir())
    assert figures == sorted(f"case_{s}_{p}_ngsim.png" for p in ("physical", "paper") for s in ("radar", "camera"))
    assert case_study.print_case_study([str(results)]) == 0 and len(list((tmp_path / "a=b").iterdir())) == 4


@pytest.mark.parametrize("content", [None, "{"])
def test_a_missing_or_malformed_file_is_one_line(tmp_path, content, capsys):
    path = tmp_path / "r.json"
    if content is not None:
        path.write_text(content)
    with pytest.raises(SystemExit) as e:
        run(lambda: command.main([str(path)]))
    err = capsys.readouterr().err
    assert e.value.code == 2 and err.startswith(f"error: {path}") and err.count("\n") == 1


def _comparison(a: str, b: str, diff: float, ci: list[float] | None, **extra) -> dict:
    return {"a": a, "b": b, "diff_m": diff, "ci": ci, "ci_unpaired": ci, "paired": True, "verdict": "", **extra}


def _with_intervals() -> dict:
    """DATA with the intervals a current results file holds: each step's E_ci, each run's
    comparisons against its best step, and the file's radar-against-camera comparisons."""
    data = json.loads(json.dumps(DATA))
    for run in data["runs"]:
        e = [s["E_hard"] for s in run["steps"]]
        best = STEPS[e.index(min(e))]
        for s in run["steps"]:
            s["E_ci"] = [s["E_hard"] - 0.25, s["E_hard"] + 0.25]
        run["comparisons"] = [_comparison(f"{r:g} deg", f"{best:g} deg", v - min(e),
                                          [v - min(e) - 0.1, v - min(e) + 0.1]) for r, v in zip(STEPS, e) if r != best]
    radar = {p: next(r for r in data["runs"] if (r["profile"], r["sensor"], r["fill"]) == (p, "radar", f))
             for p, f in (("physical", "hold"), ("paper", "zero"))}
    camera = {p: next(r for r in data["runs"] if (r["profile"], r["sensor"]) == (p, "camera")) for p in radar}
    data["comparisons"] = [
        _comparison(f"radar at {r:g} deg", f"camera at {r:g} deg", d, [d - 0.6, d + 0.6], weights="ngsim", profile=p,
                    r=r, of="sensors")
        for p in radar for k, r in enumerate(STEPS)
        for d in [radar[p]["steps"][k]["E_hard"] - camera[p]["steps"][k]["E_hard"]]]
    return data


def test_intervals_in_the_file_reach_the_tables_and_the_statements(tmp_path, capsys):
    data = _with_intervals()
    runs = case_study.index_runs([data])
    rows = _cells(case_study.pooled(runs, ["ngsim"], STEPS))
    assert rows[1] == ["", "", "", "90% CI", "[1.75, 2.25]", "[1.25, 1.75]", "[1.25, 1.75]", ""]  # radar, physical (1.755: 1.75 in binary)
    # every step against the run's best (physical radar: best 60 deg), paired
    assert _cells(case_study.against_best(runs, STEPS))[0] == ["ngsim", "physical", "radar", "+0.50 [0.40, 0.60]",
                                                               "best", "+0.00 [-0.10, 0.10]"]  # +0.005
    # radar - camera: physical 2.0 - 3.0, 1.5 - 2.75, 1.505 - 2.5; paper 4 - 1, 3 - 3, 2 - 3.5
    assert _cells(case_study.radar_against_camera(data["comparisons"], STEPS)) == [
        ["ngsim", "physical", "-1.00 [-1.60, -0.40]", "-1.25 [-1.85, -0.65]", "-1.00 [-1.60, -0.40]"],
        ["ngsim", "paper", "+3.00 [2.40, 3.60]", "+0.00 [-0.60, 0.60]", "-1.50 [-2.10, -0.90]"]]
    physical, paper = case_study.statements(runs, ["ngsim"], STEPS, data["comparisons"]).splitlines()
    # (1) below camera at 3 steps, all 3 clear of the interval; (2) worse than 60 deg by more than the
    # interval at 1 of the 2 other steps (30 deg; 90 deg's +0.005 is not)
    assert "at 3 of 3 steps (3 by more than the paired 90 % interval)" in physical
    assert "at 1 of 2 other steps" in physical
    assert "at 1 of 3 steps (1 by more than the paired 90 % interval)" in paper and "at 2 of 2 other steps" in paper
    results = tmp_path / "r.json"
    results.write_text(json.dumps(data))
    assert case_study.print_case_study([str(results)]) == 0
    assert len([line for line in capsys.readouterr().out.splitlines() if line.startswith("### ")]) == 7
