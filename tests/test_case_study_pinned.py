"""The case study's tables and statements from a results file written by hand: each table whole
(numbers to two decimals, the profile's own fill, the best step within 1 cm, flat scenarios,
the horizon's whole seconds), the three statements word for word, the printed page, the figures
asked for, and a missing or malformed file refused by one line."""

from __future__ import annotations

import json

import pytest

from diffsense.report import _figures, case_study

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
        _run("paper", "camera", "zero", [1.0, 3.0, 3.5], {"RLC": [1.0, 3.0, 3.5], "LLC": [1.0, 3.0, 3.5]}),  # a tie at 60
    ],
}
RUNS = case_study.index_runs([DATA])


def _lines(*rows: str) -> str:
    return "\n".join(rows)


def test_the_best_step_is_every_step_within_a_centimetre_of_the_least():
    assert case_study._best([2.0, 1.5, 1.505], STEPS) == "60-90"
    assert case_study._best([2.0, 1.5, 1.52], STEPS) == "60"
    assert case_study._best([1.0, 1.01, 1.0101], STEPS) == "30-60"
    assert case_study._best([1.5, 1.0, 1.5], STEPS, tol_m=0.6) == "30-90"


def test_the_pooled_table_reads_each_profile_with_its_own_fill():
    assert case_study.pooled(RUNS, ["ngsim"], STEPS) == _lines(
        "| weights | profile | sensor | [m] | 30 deg | 60 deg | 90 deg | best |",
        "|---|---|---|---|---|---|---|---|",
        "| ngsim | physical | radar | E_hard | 2.00 | 1.50 | 1.50 | 60-90 |",
        "|  |  |  | E_tracked | 1.00 | 0.75 | 0.75 | 60-90 |",
        "|  |  |  | missed share | 0.00 | 0.10 | 0.20 |  |",
        "| ngsim | physical | camera | E_hard | 3.00 | 2.75 | 2.50 | 90 |",
        "|  |  |  | E_tracked | 1.50 | 1.38 | 1.25 | 90 |",
        "|  |  |  | missed share | 0.00 | 0.10 | 0.20 |  |",
        "| ngsim | paper | radar | E_hard | 4.00 | 3.00 | 2.00 | 90 |",
        "|  |  |  | E_tracked | 2.00 | 1.50 | 1.00 | 90 |",
        "|  |  |  | missed share | 0.00 | 0.10 | 0.20 |  |",
        "| ngsim | paper | camera | E_hard | 1.00 | 3.00 | 3.50 | 30 |",
        "|  |  |  | E_tracked | 0.50 | 1.50 | 1.75 | 30 |",
        "|  |  |  | missed share | 0.00 | 0.10 | 0.20 |  |")


def test_a_scenario_flatter_than_a_centimetre_has_no_best_or_worst():
    table = case_study.per_scenario(RUNS, STEPS).splitlines()
    assert table[:4] == [
        "| weights | profile | sensor | scenario | 30 | 60 | 90 | best | worst |",
        "|---|---|---|---|---|---|---|---|---|",
        "| ngsim | physical | radar | RLC | 2.00 | 1.50 | 1.50 | 60-90 | 30 |",
        "| ngsim | physical | radar | LLC | 1.00 | 1.00 | 1.00 | flat |  |"]
    assert table[-1] == "| ngsim | paper | camera | LLC | 1.00 | 3.00 | 3.50 | 30 | 90 |"
    assert len(table) == 2 + 4 * 2
    edge = case_study.index_runs([{"runs": [_run("paper", "camera", "zero", [0.0, 0.01, 0.005],
                                                  {"EDGE": [0.0, 0.01, 0.005]})]}])
    assert case_study.per_scenario(edge, STEPS).endswith("| EDGE | 0.00 | 0.01 | 0.01 | 30-90 | 60 |")  # 1 cm: not flat


def test_the_imputation_table_holds_every_radar_fill():
    assert case_study.imputation(RUNS, STEPS) == _lines(
        "| weights | profile | fill | 30 deg | 60 deg | 90 deg |", "|---|---|---|---|---|---|",
        "| ngsim | physical | hold | 2.00 | 1.50 | 1.50 |", "| ngsim | physical | zero | 9.00 | 9.00 | 9.00 |",
        "| ngsim | paper | zero | 4.00 | 3.00 | 2.00 |")


def test_the_ground_truth_table_reads_whole_seconds_and_the_card():
    assert case_study.ground_truth([DATA]) == _lines(
        "| weights | scenario | 1 s | 2 s | 3 s | 4 s | 5 s |", "|---|---|---|---|---|---|---|",
        "| ngsim | RLC | 0.50 | 1.00 | 1.50 | 2.00 | 2.50 |", "| ngsim | LLC | 1.50 | 2.00 | 2.50 | 3.00 | 3.50 |",
        "| ngsim | card / published | 0.50 | 1.25 | 2.00 | 3.00 | 4.50 |")


def test_the_three_statements_word_for_word():
    assert case_study.statements(RUNS, ["ngsim"], STEPS).splitlines() == [
        ("- ngsim, physical: (1) radar below camera at 3 of 3 steps; (2) radar's best step(s) 60-90 deg "
         "(30 deg: 2.00 m, best 1.50 m); (3) camera's worst step 30 deg, spread above 30 deg 0.25 m"),
        ("- ngsim, paper: (1) radar below camera at 1 of 3 steps; (2) radar's best step(s) 90 deg "
         "(30 deg: 4.00 m, best 2.00 m); (3) camera's worst step 90 deg, spread above 30 deg 0.50 m")]


def test_the_page_prints_every_section_and_asks_for_four_figures(tmp_path, monkeypatch, capsys):
    drawn = []
    monkeypatch.setattr(_figures, "plot_rmse_horizon", lambda path, curves, **kw: drawn.append((path, curves, kw)))
    results = tmp_path / "r.json"
    results.write_text(json.dumps(DATA))
    assert case_study.main([str(results), f"--figure-dir={tmp_path}"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("Computed by benchmarks/case_study.py on jax 0.0.1 (cpu, 2 CPU cores), 8 variants per "
                          "scenario.\n\n### Pooled, both questions\n\n| weights | profile |")
    titles = [line for line in out.splitlines() if line.startswith("### ")]
    assert titles == ["### Pooled, both questions", "### E_hard per scenario", "### Radar imputation: E_hard per fill",
                      "### Ground-truth-input RMSE against the true future [m]", "### The paper's three statements"]
    assert f"### The paper's three statements\n\n{case_study.statements(RUNS, ['ngsim'], STEPS)}\n\n" in out
    assert [path for path, _, _ in drawn] == [f"{tmp_path}/case_{s}_{p}_ngsim.png" for p in ("physical", "paper")
                                             for s in ("radar", "camera")]
    _, curves, kw = drawn[0]
    assert kw == {"param": "HFOV", "unit": "deg", "title": "ngsim / physical / radar / hold"}
    assert list(curves) == ["RLC", "LLC"] and curves["LLC"]["gt"] == [h + 1 for h in HORIZON]
    assert curves["RLC"]["steps"] == {r: [h + k for h in HORIZON] for k, r in enumerate(STEPS)}
    assert case_study.main([str(results)]) == 0 and len(drawn) == 4  # no --figure-dir: no figures
    monkeypatch.setattr(case_study.sys, "argv", ["case_study", str(results), f"--figure-dir={tmp_path}/a=b"])
    assert case_study.main() == 0 and drawn[-1][0] == f"{tmp_path}/a=b/case_camera_paper_ngsim.png"


@pytest.mark.parametrize("content, message", [
    (None, "{path}: No such file or directory"),
    ("{", "{path}: not a results file: Expecting property name enclosed in double quotes: line 1 column 2 (char 1)"),
])
def test_a_missing_or_malformed_file_is_one_line(tmp_path, content, message, capsys):
    path = tmp_path / "r.json"
    if content is not None:
        path.write_text(content)
    with pytest.raises(SystemExit) as e:
        case_study.console([str(path)])
    assert e.value.code == 2 and capsys.readouterr().err == f"error: {message.format(path=path)}\n"
