"""Notebook 04 (the paper's case study): its written conclusions against its own stored outputs
(fast: no kernel runs; see test_notebook_claims.py). The tables are the markdown the notebook
displays (`diffsense.report.case_study`); the statements are its printed verdict lines."""

from __future__ import annotations

import json

import numpy as np

from tests._notebook_text import NOTEBOOKS, printed, prose, says

NB04 = "04_case_study"
STEPS = [30, 60, 90, 120, 150, 180]


def _markdown_tables() -> list[list[list[str]]]:
    """Every markdown table the notebook displayed: rows of cells (header first, rule dropped)."""
    cells = json.loads((NOTEBOOKS / f"{NB04}.ipynb").read_text())["cells"]
    out = []
    for cell in cells:
        for o in cell.get("outputs", []):
            text = "".join(o.get("data", {}).get("text/markdown", ""))
            rows = [[c.strip() for c in ln.strip().strip("|").split("|")] for ln in text.splitlines() if ln.startswith("|")]
            if rows:
                out.append([r for r in rows if not set("".join(r)) <= set("-")])
    return out


def _table(first_header: str, second: str) -> list[list[str]]:
    return next(t for t in _markdown_tables() if t[0][0] == first_header and t[0][1] == second)


def _pooled() -> dict[tuple[str, str, str, str], list[float]]:
    """(weights, profile, sensor, row) -> the 6 step values, from the pooled table."""
    out, key = {}, None
    for row in _table("weights", "profile")[1:]:
        if row[0]:
            key = tuple(row[:3])
        if row[3] != "90% CI":  # the E_hard row's interval: "[lo, hi]" cells
            out[(*key, row[3])] = [float(x) for x in row[4:10]]
    return out


def test_04_the_three_statements():
    words = prose(NB04, "## Conclusions")
    says(words, "6 of 6 steps, each clearly, with the paper profile for both weights; with the physical profile 4 of 6 "
                "(shipped, 2 clearly: 30 and 60 deg) and 6 of 6 (NGSIM, 4 clearly)",
         "clearly against every other step (shipped 48.90 m against 58.77 m at 180 deg)",
         "30 deg is the *worst* step (47.78 m against 46.86 m, equal from 60 to 180 deg)",
         "every other scenario is flat", "(60-180 deg within 0.02 m)")
    verdicts = printed(NB04, "radar below camera")
    for pair, wins, clear in (("shipped, physical", 4, 2), ("shipped, paper", 6, 6), ("ngsim, physical", 6, 4),
                              ("ngsim, paper", 6, 6)):
        assert f"- {pair}: (1) radar below camera at {wins} of 6 steps ({clear} by more than" in verdicts, pair
    for pair in ("shipped, physical", "ngsim, physical"):  # 30 deg told from every other step
        line = next(ln for ln in verdicts.splitlines() if ln.startswith(f"- {pair}:"))
        assert "best step(s) 30 deg" in line and "at 5 of 5 other steps" in line, line
    e = _pooled()
    phys = e[("shipped", "physical", "radar", "E_hard")]
    assert (phys[0], phys[-1]) == (48.90, 58.77) and np.argmin(phys) == 0
    paper = e[("shipped", "paper", "radar", "E_hard")]
    assert paper[0] == 47.78 and set(paper[1:]) == {46.86}
    for w in ("shipped", "ngsim"):
        camera = e[(w, "paper", "camera", "E_hard")]
        assert np.argmax(camera) == 0 and max(camera[1:]) - min(camera[1:]) <= 0.02 + 1e-9, camera
        physical_camera = e[(w, "physical", "camera", "E_hard")]
        assert np.all(np.diff(physical_camera) > 0), physical_camera  # "gets worse with HFOV"
    # Per scenario, paper profile: the cut-in scenarios lose at 30 deg, all others are flat.
    per = next(t for t in _markdown_tables() if t[0][3] == "scenario")[1:]
    for w, profile, sensor, scenario, *rest in per:
        if profile == "paper" and sensor == "radar":
            worst = rest[-1]
            assert (worst == "30") if scenario in ("sc01", "sc02") else (rest[-2] == "flat"), (w, scenario, rest)


def test_04_tracked_imputation_domain():
    words = prose(NB04, "## Conclusions")
    says(words, "missed share grows from 0.24 to 0.51 with HFOV", "it moves within 34.06-38.05 m with no trend (shipped) or falls (NGSIM)",
         "Fill `zero` has the lowest E_hard everywhere; `interp` and `hold` differ by at most 0.31 m",
         "within 0.89-1.34x of their card on every scenario", "49-56 m off at 5 s")
    e = _pooled()
    missed = e[("shipped", "physical", "radar", "missed share")]
    assert (missed[0], missed[-1]) == (0.24, 0.51)
    shipped = e[("shipped", "physical", "radar", "E_tracked")]
    ngsim = e[("ngsim", "physical", "radar", "E_tracked")]
    assert np.all(np.diff(missed) > 0)
    # no trend: neither rising nor falling across the steps, between the range the prose names
    assert not (np.all(np.diff(shipped) >= 0) or np.all(np.diff(shipped) <= 0))
    assert (min(shipped), max(shipped)) == (34.06, 38.05) and ngsim[-1] < ngsim[0]
    fills: dict[tuple[str, str], dict[str, list[float]]] = {}
    for w, profile, fill, *v in next(t for t in _markdown_tables() if t[0][2] == "fill")[1:]:
        fills.setdefault((w, profile), {})[fill] = [float(x) for x in v]
    for key, f in fills.items():
        assert np.all(np.asarray(f["zero"]) <= np.minimum(f["hold"], f["interp"])), key
        assert np.max(np.abs(np.subtract(f["interp"], f["hold"]))) <= 0.31 + 1e-9, key
    gt = next(t for t in _markdown_tables() if t[0][:2] == ["weights", "scenario"])[1:]
    card = {r[0]: [float(x) for x in r[2:]] for r in gt if r[1] == "card / published"}
    # per scenario, the largest ratio over the horizons (from the table's 2-decimal figures)
    worst = [max(float(x) / c for x, c in zip(r[2:], card["shipped"])) for r in gt
             if r[0] == "shipped" and r[1] != "card / published"]
    assert len(worst) == 6 and (round(min(worst), 2), round(max(worst), 2)) == (0.89, 1.34), worst
    five_s = [float(r[6]) for r in gt if r[0] == "ngsim" and r[1] in ("sc05", "sc06")]
    assert 49 <= min(five_s) and max(five_s) < 56.5, five_s
