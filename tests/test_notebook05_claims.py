"""Notebook 05's written conclusions against the stored design benchmark results it reads (fast: no
kernel runs, no benchmark runs).

Every number the conclusions quote and every comparison they state is recomputed here from
benchmarks/results/design_d{8,16,28}.json, so a re-run of the benchmark that changes a result fails
until the prose says what the new results show. The last test holds docs/suite.md's table of the
earlier comparison (threshold law, `suite_d{4,8,16}.json`) to its stored results.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from tests._notebook_text import printed, prose, says

NB05 = "05_suite_design"
RESULTS = Path(__file__).resolve().parents[1] / "benchmarks" / "results"
BASELINES = ("CMA-ES", "TPE", "GP", "random")


def _design(d: int) -> dict:
    return json.loads((RESULTS / f"design_d{d}.json").read_text())


def _evals(values) -> float:
    return float(np.median([math.inf if v is None else v for v in values]))


def _judged(res: dict, method: str) -> float:
    return float(np.median(res["methods"][method]["best_judged"]))


def _words() -> str:
    return prose(NB05, "## Conclusions")


def test_the_stored_summaries_are_what_the_runs_say():
    for d in (8, 16, 28):
        res = _design(d)
        finals = {m: [min(j) for j in (r["judged"] for r in runs)] for m, runs in res["runs"].items()}
        assert res["best_judged_any"] == min(min(v) for v in finals.values())
        assert math.isclose(res["target"], 1.01 * res["best_judged_any"], rel_tol=1e-12)
        for method, row in res["methods"].items():
            assert len(row["best_judged"]) == len(res["runs"][method])
            for spent, run in zip(row["evals_to_within_1pct"], res["runs"][method]):
                first = next((inc[0] for inc, j in zip(run["incumbents"], run["judged"]) if j <= res["target"]), None)
                assert spent == first, (d, method)
                assert run["spent"] <= res["budget"] + 1e-9, (d, method)  # equal budgets


def test_no_plateau_failure():
    says(_words(), "**No plateau failure: met.**", "within 1.0 % (d = 8), 0.5 % (d = 16) and 3.3 % (d = 28)")
    for d, quoted in {8: 1.0, 16: 0.5, 28: 3.3}.items():
        res = _design(d)
        worst = max(res["methods"]["design"]["best_judged"]) / res["best_judged_any"] - 1
        assert round(100 * worst, 1) == quoted and worst <= 0.05


def test_ahead_of_cma_es_tpe_and_random_search():
    says(_words(), "9.953 m at d = 8 against CMA-ES's 10.169 m and TPE's 10.564 m",
         "4.666 m at d = 16 against 5.193 and 4.988 m", "4.676 m at d = 28 against 5.264 and 5.089 m")
    for d, quoted in {8: (9.953, 10.169, 10.564), 16: (4.666, 5.193, 4.988), 28: (4.676, 5.264, 5.089)}.items():
        res = _design(d)
        assert tuple(float(f"{_judged(res, m):.3f}") for m in ("design", "CMA-ES", "TPE")) == quoted, d
        for method in ("CMA-ES", "TPE", "random"):
            assert all(v is None for v in res["methods"][method]["evals_to_within_1pct"]), (d, method)
            assert _judged(res, method) > _judged(res, "design"), (d, method)


def test_the_gp_sampler_and_the_targets():
    says(_words(), "the evaluation targets are not met", "in 22 evaluations (median), the design solve in 65",
         "a ratio of 2.96 against the target of 0.5", "needs 183 against the GP's 234 (0.78 against the target of 0.2)",
         "the GP sampler was not run there")
    for d, (design, gp) in {8: (65, 22), 16: (183, 234)}.items():
        rows = _design(d)["methods"]
        assert round(_evals(rows["design"]["evals_to_within_1pct"])) == design
        assert round(_evals(rows["GP"]["evals_to_within_1pct"])) == gp
        best_baseline = min(_evals(rows[m]["evals_to_within_1pct"]) for m in BASELINES if m in rows)
        assert best_baseline == _evals(rows["GP"]["evals_to_within_1pct"])
    rows = _design(8)["methods"]
    assert f"{_evals(rows['design']['evals_to_within_1pct']) / _evals(rows['GP']['evals_to_within_1pct']):.2f}" == "2.96"
    rows = _design(16)["methods"]
    assert f"{_evals(rows['design']['evals_to_within_1pct']) / _evals(rows['GP']['evals_to_within_1pct']):.2f}" == "0.78"
    wall = {m: _evals(rows[m]["wall_to_within_1pct_s"]) for m in ("design", "GP")}
    assert wall["design"] < wall["GP"]  # "less wall time to get there"
    rows28 = _design(28)["methods"]
    assert "GP" not in rows28 and _evals(rows28["design"]["evals_to_within_1pct"]) == math.inf
    assert sum(v is not None for v in rows28["design"]["evals_to_within_1pct"]) == 1


def test_the_sample_moves_j_more_than_the_band():
    says(_words(), "6.7 % (design) and 7.4 % (GP) worse judged", "2-3 % *below* its optimised value")
    rows = _design(8)["methods"]
    gaps = {m: np.median(rows[m]["best_judged"]) / np.median(rows[m]["best_optimised"]) - 1 for m in ("design", "GP")}
    assert (round(100 * gaps["design"], 1), round(100 * gaps["GP"], 1)) == (6.7, 7.4)
    for d in (16, 28):
        rows = _design(d)["methods"]
        for method in ("design", "TPE", *(("GP",) if "GP" in rows else ())):
            gap = np.median(rows[method]["best_judged"]) / np.median(rows[method]["best_optimised"]) - 1
            assert -0.035 < gap < -0.02, (d, method, gap)


def test_the_printed_table_is_the_stored_one():
    text = printed(NB05, "design / best baseline evaluations")
    for d in (8, 16, 28):
        res = _design(d)
        assert f"best judged J {res['best_judged_any']:.4f} m" in text, d
        for method, row in res["methods"].items():
            assert f"{np.median(row['best_judged']):.4f}" in text, (d, method)


def test_docs_table_of_the_threshold_law_comparison_quotes_its_stored_results():
    text = (Path(__file__).resolve().parents[1] / "docs" / "suite.md").read_text()
    for d in (4, 8, 16):
        (res,) = json.loads((RESULTS / f"suite_d{d}.json").read_text())["results"]
        final = {m: float(np.median([min(v for _, v in r["trace"]) for r in res["runs"][m]])) for m in res["rows"]}
        finals = " | ".join(f"{final[m]:.4f}" for m in ("gradient", "CMA-ES", "TPE", "random"))
        soft = " / ".join(f"{res['rows'][m]['J_soft_at_best_median']:.4f}" for m in ("gradient", "CMA-ES", "TPE"))
        assert f"| {d} | {res['best_J']:.4f} | {finals} | {soft} |" in text, d
