"""Notebook 05's written conclusions against the stored benchmark results it reads (fast: no
kernel runs, no benchmark runs).

Every number the conclusions quote and every comparison they state is recomputed here from
benchmarks/results/suite_d{4,8,16}.json, so a re-run of the benchmark that changes a result fails
until the prose says what the new results show.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests._notebook_text import prose, says

NB05 = "05_suite_design"
RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results"


def _result(d: int) -> dict:
    (res,) = json.loads((RESULTS / f"suite_d{d}.json").read_text())["results"]
    return res


def _final(res: dict, method: str) -> float:
    return float(np.median([min(v for _, v in r["trace"]) for r in res["runs"][method]]))


def _words() -> str:
    return prose(NB05, "## Conclusions")


def test_the_stored_tables_are_what_the_runs_say():
    for d in (4, 8, 16):
        res = _result(d)
        assert res["best_J"] == min(v for rs in res["runs"].values() for r in rs for _, v in r["trace"])
        for method, row in res["rows"].items():
            assert row["final_J_median"] == pytest.approx(_final(res, method), rel=1e-12)
            assert row["J_soft_at_best_median"] == pytest.approx(
                float(np.median([r["J_soft_at_best"] for r in res["runs"][method]])), rel=1e-12)


def test_target_not_met_and_the_ranking():
    says(_words(), "**The target is not met.**", "the ratio is undefined",
         "(17.6515 m against 14.5586 and 15.1235 m; best found 14.4114 m)",
         "(16.8277 m against 14.9967 and 14.9563 m; best 14.4880 m)", "it beats only random", "within 0.6 m",
         "(48.7245 m for the gradient", "the best point 46.7517 m being one CMA-ES run's")
    for d, (grad, tpe, cma, best) in {8: (17.6515, 14.5586, 15.1235, 14.4114),
                                       16: (16.8277, 14.9967, 14.9563, 14.4880)}.items():
        res = _result(d)
        got = [round(_final(res, m), 4) for m in ("gradient", "TPE", "CMA-ES")] + [round(res["best_J"], 4)]
        assert got == [grad, tpe, cma, best], d
        assert res["gradient_over_best_baseline"] is None
        assert all(row["reached"] <= 2 for row in res["rows"].values())
        assert _final(res, "random") > _final(res, "gradient") > max(_final(res, "TPE"), _final(res, "CMA-ES"))
    res = _result(4)
    finals = [_final(res, m) for m in res["rows"]]
    assert max(finals) - min(finals) < 0.6 and round(_final(res, "gradient"), 4) == 48.7245
    best_run = min(((m, min(v for _, v in r["trace"])) for m, rs in res["runs"].items() for r in rs), key=lambda t: t[1])
    assert best_run == ("CMA-ES", pytest.approx(46.7517, abs=5e-5))


def test_the_surrogate_ranks_the_answers_the_other_way():
    says(_words(), "10.6420 m at d = 8 and 10.5905 m at d = 16", "15.2801 / 15.6533 m (CMA-ES / TPE)",
         "and 15.7058 / 16.3282 m", "the soft J rises from 10.856 to 15.378 m while the hard J falls from 17.283 to 14.411 m")
    for d in (4, 8, 16):
        rows = _result(d)["rows"]
        soft = {m: row["J_soft_at_best_median"] for m, row in rows.items()}
        assert min(soft, key=soft.get) == "gradient", d
    quoted = {8: (10.6420, 15.2801, 15.6533), 16: (10.5905, 15.7058, 16.3282)}
    for d, values in quoted.items():
        rows = _result(d)["rows"]
        assert tuple(round(rows[m]["J_soft_at_best_median"], 4) for m in ("gradient", "CMA-ES", "TPE")) == values
    line = _result(8)["line"]
    assert [round(line[i][k], 3) for i in (0, -1) for k in ("J_soft", "J_hard")] == [10.856, 17.283, 15.378, 14.411]
    assert all(a["J_soft"] < b["J_soft"] for a, b in zip(line, line[1:]))


def test_the_gain_corner_and_the_far_basins():
    says(_words(), "HFOV within 0.05 deg of its 20 deg lower bound", "within 0.05 dB of its\n  20 dBm".replace("\n  ", " "),
         "within 0.05 dB of its 3 dB lower bound", "both J climb to about 50 m")
    for r in _result(8)["runs"]["gradient"]:
        x = r["x_star"]
        assert x["radar.hfov_deg"] - 20.0 <= 0.05 and 20.0 - x["radar.tx_power_dbm"] <= 0.05
        assert x["radar.noise_figure_db"] - 3.0 <= 0.05
    line = _result(16)["line"]
    peak = max(max(p["J_hard"], p["J_soft"]) for p in line)
    assert 50.0 <= peak <= 56.0 and max(p["J_hard"] for p in line) > 50.0


def test_docs_table_quotes_the_stored_results():
    text = (Path(__file__).resolve().parents[1] / "docs" / "suite.md").read_text()
    for d in (4, 8, 16):
        res = _result(d)
        finals = " | ".join(f"{_final(res, m):.4f}" for m in ("gradient", "CMA-ES", "TPE", "random"))
        soft = " / ".join(f"{res['rows'][m]['J_soft_at_best_median']:.4f}" for m in ("gradient", "CMA-ES", "TPE"))
        assert f"| {d} | {res['best_J']:.4f} | {finals} | {soft} |" in text, d
