"""docs/suite.md's section on the suite under probabilistic laws against the stored benchmark
results it quotes (fast: no benchmark runs). Every number the section quotes is recomputed here
from benchmarks/results/suite_laws_d8.json (and the threshold re-run from suite_d8_threshold_rerun.json),
so a re-run that changes a result fails until the text says what the new results show."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SECTION = "### Under probabilistic laws: the gradient ahead at d = 8"


def _result(name: str) -> dict:
    (res,) = json.loads((ROOT / "benchmarks" / "results" / name).read_text())["results"]
    return res


def _text() -> str:
    doc = (ROOT / "docs" / "suite.md").read_text()
    return " ".join(doc[doc.index(SECTION):].split())


def _finals(res: dict, method: str) -> np.ndarray:
    return np.array([min(v for _, v in r["trace"]) for r in res["runs"][method]])


def _judged(res: dict, method: str) -> np.ndarray:
    return np.array([r["J_judged_at_best"] for r in res["runs"][method]])


def test_the_table_is_the_runs_medians():
    res, text = _result("suite_laws_d8.json"), _text()
    for method, row in res["rows"].items():
        assert row["final_J_median"] == pytest.approx(float(np.median(_finals(res, method))), rel=1e-12)
        assert row["J_judged_at_best_median"] == pytest.approx(float(np.median(_judged(res, method))), rel=1e-12)
        reached = f"{row['reached']} / 5"
        if row["reached"]:
            reached += f" (median {row['evaluations_to_1pct_median']:.0f} evaluations)"
        line = (f"| {method} | {row['final_J_median']:.4f} | {row['J_soft_at_best_median']:.4f} | {reached} | "
                f"{row['J_judged_at_best_median']:.4f} |")
        assert line in text, line
    assert f"best J any run found {res['best_J']:.4f} m, by the gradient" in text
    assert res["best_J"] == _finals(res, "gradient").min()
    assert f"c = {res['c']:.2f} evaluations of E_ref, {res['t_value_and_grad_s']:.2f} s against {res['t_hard_s']:.2f} s" in text


def test_the_gradient_leads_on_four_seeds_and_fails_on_seed_0():
    res, text = _result("suite_laws_d8.json"), _text()
    grad, judged = _finals(res, "gradient"), _judged(res, "gradient")
    ok = grad < 50
    assert ok.tolist() == [False, True, True, True, True]
    cma, tpe, rnd = (_finals(res, m) for m in ("CMA-ES", "TPE", "random"))
    assert grad[ok].max() < min(cma.min(), tpe.min())
    others = np.concatenate([_judged(res, m) for m in ("CMA-ES", "TPE", "random")])
    assert judged[ok].max() < others.min()
    reach = [x for x in res["rows"]["gradient"]["evaluations_to_1pct"] if x is not None]
    assert all(res["rows"][m]["reached"] == 0 for m in ("CMA-ES", "TPE", "random"))
    ranges = {"gradient": (grad[ok].min(), grad[ok].max()), "CMA-ES": (cma.min(), cma.max()),
              "random": (rnd.min(), rnd.max()), "judged": (judged[ok].min(), judged[ok].max()),
              "judged CMA-ES": (_judged(res, "CMA-ES").min(), _judged(res, "CMA-ES").max()),
              "judged TPE": (_judged(res, "TPE").min(), _judged(res, "TPE").max())}
    for lo, hi in ranges.values():
        assert f"{lo:.4f}-{hi:.4f} m" in text, (lo, hi)
    assert f"after {min(reach):.0f}-{max(reach):.0f} evaluations" in text
    assert f"the solve ends at {grad[0]:.4f} m" in text
    seed0 = [v for _, v in res["runs"]["gradient"][0]["trace"]]
    assert len(seed0) == 26 and res["runs"]["gradient"][0]["counts"] == {"soft": 37, "hard": 26}
    assert f"J between {min(seed0[:18]):.2f} and {max(seed0[:18]):.2f} m" in text
    assert f"the 8 answers its levels gave: {min(seed0[18:]):.2f}-{max(seed0[18:]):.2f} m" in text


def test_the_surrogate_and_the_draws():
    res, text = _result("suite_laws_d8.json"), _text()
    gaps = [abs(r["J_soft_at_best"] / min(v for _, v in r["trace"]) - 1) for rs in res["runs"].values() for r in rs]
    assert max(gaps) < 0.014 and "within 1.4 % of its E_ref J" in text
    luck = {m: 100 * (_judged(res, m) / _finals(res, m) - 1) for m in res["runs"]}
    ok = _finals(res, "gradient") < 50
    assert f"{luck['gradient'][ok].min():.1f}-{luck['gradient'][ok].max():.1f} % worse" in text
    cma = luck["CMA-ES"]
    assert f"from {-cma.min():.1f} % better to {cma.max():.1f} % worse" in text
    lowest = np.argsort(_finals(res, "CMA-ES"))[:2]
    assert (cma[lowest] > 0).all() and (np.delete(cma, lowest) < 0).all()
    rest = np.concatenate([luck["TPE"], luck["random"]])
    assert f"from {-rest.min():.1f} % better to {rest.max():.1f} % worse" in text
    for r in res["runs"]["gradient"][1:]:  # the radar's gain corner
        x = dict(zip(res["names"], r["x_best"]))
        assert x["radar.hfov_deg"] == pytest.approx(20, abs=0.01) and x["radar.noise_figure_db"] == pytest.approx(3, abs=0.01)
        assert x["radar.tx_power_dbm"] == pytest.approx(20, abs=0.01)


def test_the_threshold_rerun_matches_the_stored_table():
    old, new = _result("suite_d8.json"), _result("suite_d8_threshold_rerun.json")
    for method in ("CMA-ES", "TPE", "random"):
        assert round(new["rows"][method]["final_J_median"], 4) == round(old["rows"][method]["final_J_median"], 4)
    assert round(new["best_J"], 4) == round(old["best_J"], 4)
    doc = " ".join((ROOT / "docs" / "suite.md").read_text().split())
    assert (f"the gradient's median is {new['rows']['gradient']['final_J_median']:.4f} m (c measured "
            f"{new['c']:.2f} there against {old['c']:.2f}") in doc
