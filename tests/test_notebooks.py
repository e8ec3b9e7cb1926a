"""The notebooks: the committed copies carry outputs, figures and no error; in fast mode
(DIFFSENSE_NOTEBOOK_FAST=1: one scenario, one variant, a few points) each runs top to bottom and
the claims its text makes that hold at any size are checked on what the run computed.

Each fast run appends one cell that writes the kernel's numbers to a JSON file (`FACTS`); the
tests read that file. A fast run takes minutes on the 2-core machine, hence `slow`.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"
_spec = importlib.util.spec_from_file_location("notebook_execute", NOTEBOOKS / "execute.py")
execute = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(execute)

PATHS = execute.notebooks([])
FACTS_ENV = "DIFFSENSE_NOTEBOOK_FACTS"

# Per notebook: the extra cell's code, run after the notebook's own; `dump` writes its JSON.
_DUMP = "import json as _json, os as _os, numpy as _np\n" \
        "def dump(x): _json.dump(x, open(_os.environ['" + FACTS_ENV + "'], 'w'), default=lambda a: _np.asarray(a).tolist())\n"
FACTS = {
    "01": _DUMP + """dump({
    "fd": {f"{s} {p}": rows for (s, p), rows in FD.items()},
    "decomp": [{"sensor": s, "r": r, "c": float(c.sum()), "dc": float(dc.sum()),
                "e2": value_and_slope(PROBLEMS[s, "hfov_deg"], r)[0], "g": value_and_slope(PROBLEMS[s, "hfov_deg"], r)[1]}
               for (s, r), (c, dc) in DECOMP.items()],
    "temp": {f"{s} {t:g}": TEMP[s, t]["E"] for s in ("radar", "camera") for t in TAUS},
    "hard": {s: HFOV[s]["E_hard"][::TEMP_STRIDE] for s in ("radar", "camera")},
})
""",
    "02": _DUMP + """dump({"main": {"rows": [vars(r) for r in rows], "pareto": front, "ref": {k: v for k, v in vars(ref).items() if k != "dense"},
                   "interval": [lo, hi]},
      "interior": {"rows": [vars(r) for r in rows_in], "pareto": front_in,
                   "ref": {k: v for k, v in vars(ref_in).items() if k != "dense"}, "interval": list(INTERIOR)}})
""",
    "03": _DUMP + """dump([{"interval": c.setting.interval, "step": c.setting.dense_step, "best": c.best,
       "dense_r": c.dense.r, "dense_E": c.dense.E_hard,
       "runs": [{"name": r.name, "r_star": r.r_star, "E_hard_star": r.E_hard_star, "counts": r.counts,
                 "trace": [vars(e) for e in r.trace]} for r in c.runs]} for c in (comp_hfov, comp_narrow)])
""",
    "04": _DUMP + """dump({
    "steps": STEPS, "names": NAMES, "timeline": TIMELINE,
    "runs": {"|".join(k): {"E": [s["E_hard"] for s in v["steps"]], "gt": v["rmse_gt"],
                           "sc01": [s["by_scenario"]["sc01"]["E_hard"] for s in v["steps"]]} for k, v in RUNS.items()},
})
""",

    "05": _DUMP + """dump({str(d): res for d, res in RESULTS.items()})
""",
    "06": _DUMP + """dump({"rows": [vars(r) for r in ROWS], "checks": [vars(c) for c in checks(ROWS)],
      "interval": list(CAMERA_HFOV_DEG), "grids": {"rain_mm_h": RAIN_MM_H, "fog_visibility_m": FOG_VISIBILITY_M,
                                                  "traffic_speed_kmh": SPEED_OFFSET_KMH}})
""",
}


def test_the_notebooks_exist():
    names = [p.name[:2] for p in PATHS]
    assert {"01", "02", "03", "04", "05", "06"} <= set(names), names


@pytest.mark.parametrize("path", PATHS, ids=[p.stem for p in PATHS])
def test_committed_notebook_is_executed_with_figures_and_no_error(path):
    nb = json.loads(path.read_text())
    code = [c for c in nb["cells"] if c["cell_type"] == "code"]
    assert code and all(c.get("execution_count") for c in code), "not executed top to bottom"
    outputs = [o for c in code for o in c.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"], "an error output"
    assert any("image/png" in o.get("data", {}) for o in outputs), "no figure"
    assert path.stat().st_size < 2_000_000
    # Public API only: no private module of diffsense, no sys.path edits, no benchmark imports.
    source = "\n".join("".join(c["source"]) for c in code)
    for banned in ("sys.path", "diffsense._", "from diffsense import _", "import bench_"):
        assert banned not in source, banned
    first = "".join(nb["cells"][0]["source"])
    assert f"python notebooks/execute.py {path.name[:2]}" in first and "Stored outputs" in first


def _fast_facts(prefix: str, tmp_path_factory) -> dict:
    path = next(p for p in PATHS if p.name.startswith(prefix))
    facts = tmp_path_factory.mktemp(f"nb{prefix}") / "facts.json"
    with pytest.MonkeyPatch.context() as mp:
        # A private compilation cache shared by the notebooks of this session (same fast shapes).
        mp.setenv("XDG_CACHE_HOME", str(NOTEBOOKS.parent / ".pytest_cache" / "notebook-xla"))
        mp.delenv("DIFFSENSE_NO_CACHE", raising=False)  # (conftest turns the user's cache off)
        mp.setenv("MPLBACKEND", "Agg")
        mp.setenv(FACTS_ENV, str(facts))
        execute.execute(path, fast=True, timeout_s=900, write=False, extra_code=FACTS[prefix])
    return json.loads(facts.read_text())


@pytest.mark.slow
def test_01_fast_gradient_checks_hold(tmp_path_factory):
    f = _fast_facts("01", tmp_path_factory)
    # Section 2 and the summary: away from a kink the automatic derivative is exact, and the
    # smaller-step central difference agrees with it (1e-9 or better, 5e-6 for radar range, in
    # full mode) wherever the derivative stands well above the rounding floor.
    checked = 0
    for name, rows in f["fd"].items():
        for row in rows:
            if abs(row["fd"][0]) > 1e3 * row["floor"][0]:
                checked += 1
                assert min(row["rel"]) < 1e-4, (name, row)
    assert checked >= 5, f["fd"]
    # Section 3: the parts add up to the objective's own value and gradient.
    assert f["decomp"]
    for d in f["decomp"]:
        assert d["c"] == pytest.approx(d["e2"], rel=1e-10)
        assert d["dc"] == pytest.approx(d["g"], rel=1e-8, abs=1e-12 * abs(d["e2"]))
    # Section 4: as tau shrinks below the solver's final x 1 the soft curve approaches the hard
    # one (the gates tend to the hard indicators): the mean gap falls at every step x 1 -> x 0.5 ->
    # x 0.25. (That it falls at every step from x 4 down, and that the soft curve sits below the
    # hard one at x 1, are full-size findings: on the fast run's one scene and three points the
    # radar's x 2 curve crosses the hard one, its mean gap 0.07 m against 0.13 m at x 0.25.)
    for sensor, hard in f["hard"].items():
        gaps = [np.mean(np.abs(np.asarray(f["temp"][f"{sensor} {t:g}"]) - np.asarray(hard)))
                for t in (0.25, 0.5, 1.0)]
        assert gaps[0] < gaps[1] < gaps[2], (sensor, gaps)


def _pareto(rows):
    """Rows no other row beats on both run time and dE_hard (written apart from the benchmark's)."""
    keep = set()
    for i, a in enumerate(rows):
        beaten = any(b["run_s"] <= a["run_s"] and b["dE_hard"] <= a["dE_hard"]
                     and (b["run_s"] < a["run_s"] or b["dE_hard"] < a["dE_hard"]) for b in rows)
        if not beaten:
            keep.add(i)
    return keep


@pytest.mark.slow
def test_02_fast_rows_are_scored_on_the_reference(tmp_path_factory):
    f = _fast_facts("02", tmp_path_factory)
    for problem in ("main", "interior"):
        rows, ref, (lo, hi) = f[problem]["rows"], f[problem]["ref"], f[problem]["interval"]
        assert [r["knob"] for r in rows][0] == "default" and len(rows) >= 5
        # r*_ref is the best point of the reference grid.
        assert ref["E_star"] == pytest.approx(min(ref["E_hard"]))
        assert ref["r_star"] == pytest.approx(ref["r"][int(np.argmin(ref["E_hard"]))])
        for r in rows:
            assert lo <= r["r_star"] <= hi
            # dE_hard = E_hard_ref(r*) - E_hard_ref(r*_ref); |r* - r*_ref|.
            assert r["dE_hard"] == pytest.approx(r["E_hard_ref"] - ref["E_star"], abs=1e-12)
            assert r["dr"] == pytest.approx(abs(r["r_star"] - ref["r_star"]))
        # The temperature is a traced argument and the hard estimator runs only the hard
        # program: those rows reuse the default's compiled problem (marked *).
        for r in rows:
            if r["knob"] == "temperature" or r["label"] == "hard":
                assert r["shared"], r
        assert set(f[problem]["pareto"]) == _pareto(rows)


@pytest.mark.slow
def test_03_fast_methods_are_counted_as_described(tmp_path_factory):
    comps = _fast_facts("03", tmp_path_factory)
    assert len(comps) == 2
    for c in comps:
        (lo, hi), step = c["interval"], c["step"]
        runs = {r["name"].split(" (")[0].split(",")[0]: r for r in c["runs"]}
        # The dense grid: every `step` from the lower bound, and the upper bound, hard only; the
        # stepped grid: six steps, hard only.
        r = np.asarray(c["dense_r"])
        gaps = np.diff(r)
        assert r[0] == lo and r[-1] == hi and np.allclose(gaps[:-1], step) and 0 < gaps[-1] <= step + 1e-9
        assert runs["dense grid"]["counts"] == {"hard": len(r), "soft": 0, "grad": 0}
        grid = next(r for name, r in runs.items() if name in ("paper grid", "stepped grid"))
        assert grid["counts"] == {"hard": 6, "soft": 0, "grad": 0}
        # Brent: once on E_hard (hard only), once on the soft E^2 (value only, no gradient).
        assert runs["bounded Brent on E_hard"]["counts"]["soft"] == runs["bounded Brent on E_hard"]["counts"]["grad"] == 0
        assert runs["bounded Brent on E_soft"]["counts"]["hard"] == runs["bounded Brent on E_soft"]["counts"]["grad"] == 0
        for r in c["runs"]:
            # Counts are programs that ran: a memoised hard point is never run again by one method
            # (soft points are memoised by r and temperature, which the trace does not record).
            points = [e["r"] for e in r["trace"] if e["kind"] == "hard"]
            assert len(points) == len(set(points)) == r["counts"]["hard"], r["name"]
            # "E_hard - best" is against the lowest E_hard any method evaluated.
            assert r["E_hard_star"] >= c["best"] - 1e-12
        # The continuous solve chooses its answer on E_hard after the sweep: never worse than the
        # best of its own steps (the stepped grid's answer).
        solve = c["runs"][0]
        assert solve["name"].startswith("continuous solve")
        assert solve["E_hard_star"] <= grid["E_hard_star"] + 1e-12


@pytest.mark.slow
def test_04_fast_case_study_claims(tmp_path_factory):
    f = _fast_facts("04", tmp_path_factory)
    assert f["names"] == ["sc01"] and f["steps"] == [30.0, 180.0]
    runs = f["runs"]
    # Every (profile, sensor, fill) of one predictor feeds it the same ground truth.
    gts = [np.asarray(r["gt"]) for r in runs.values()]
    for gt in gts[1:]:
        assert np.array_equal(gt, gts[0])
    # Conclusions (2) and (3): the Sc-01 cut-in enters from about 30 deg azimuth, so in the paper
    # profile the 30 deg radar and camera are worse than 180 deg there.
    for sensor, fill in (("radar", "zero"), ("camera", "zero")):
        e = runs[f"shipped|paper|{sensor}|{fill}"]["sc01"]
        assert e[0] > e[1], (sensor, e)
    # The physical radar's link budget does not save 30 deg in Sc-01 either (Sc-01: 16.5 vs 2.4 m).
    e = runs["shipped|physical|radar|hold"]["sc01"]
    assert e[0] > 2 * e[1], e
    # Detection timelines: in Sc-01 (nominal) the narrow physical radar sees the target in 0.79
    # of the frames and the wide one in all of them.
    assert f["timeline"]["name"] == "sc01"
    shares = {row[0]: row[1] for row in f["timeline"]["shares"]}
    assert round(shares["radar physical 30 deg"], 2) == 0.79 and shares["radar physical 180 deg"] == 1.0, shares


@pytest.mark.slow
def test_05_fast_design_claims(tmp_path_factory):
    (res,) = _fast_facts("05", tmp_path_factory).values()
    assert res["d"] == 4 and set(res["runs"]) == set(res["methods"]) == {"design", "random"}
    # Equal budgets: no run spends more than the budget (in value-evaluation cost).
    for method, runs in res["runs"].items():
        for r in runs:
            assert 0 < r["spent"] <= res["budget"] + 1e-9, method
            spent = [inc[0] for inc in r["incumbents"]]
            assert spent == sorted(spent) and len(r["judged"]) == len(r["incumbents"]), method
            # an incumbent is a run's best J so far: its optimised value never rises
            optimised = [inc[2] for inc in r["incumbents"]]
            assert all(b <= a for a, b in zip(optimised, optimised[1:])), method
            for inc in r["incumbents"]:  # every answer inside the box
                assert all(lo <= x <= hi for x, (lo, hi) in zip(inc[3], res["bounds"].values())), method
    # "the best judged J any run found" is the least judged incumbent, the 1 % target follows from it,
    # and a run's evaluations to it are those spent when its judged incumbent first got there.
    judged = [j for rs in res["runs"].values() for r in rs for j in r["judged"]]
    assert res["best_judged_any"] == min(judged) and res["target"] == pytest.approx(1.01 * min(judged), rel=1e-12)
    for method, row in res["methods"].items():
        for e, r in zip(row["evals_to_within_1pct"], res["runs"][method]):
            hits = [inc[0] for inc, j in zip(r["incumbents"], r["judged"]) if j <= res["target"]]
            assert e == (hits[0] if hits else None), method
        assert row["best_judged"] == [r["judged"][-1] for r in res["runs"][method]], method


@pytest.mark.slow
def test_06_fast_sensitivity_claims(tmp_path_factory):
    f = _fast_facts("06", tmp_path_factory)
    rows = [r for r in f["rows"] if r["sensor"] == "camera"]
    # One camera solve per asked value of each theta, every answer inside the interval.
    for theta, values in f["grids"].items():
        assert [r["value"] for r in rows if r["theta"] == theta] == list(values), theta
    lo, hi = f["interval"]
    for r in rows:
        assert lo <= r["r_star"] <= hi and lo <= r["r_soft"] <= hi, r
        if r["on_bound"]:  # "On a bound the derivative is 0"
            assert r["slope"] == 0.0, r
    # Section 1: in clear weather the camera's optimum is interior (full mode: the theorem gives a number).
    by_value = {(r["theta"], r["value"]): r for r in rows}
    base = by_value[("rain_mm_h", 0.0)]
    # (In fast mode the soft optimum may sit where E's curvature is not positive, and the theorem
    # then gives no number: `slope` is None, never a non-finite value.)
    assert not base["on_bound"] and (base["slope"] is None or np.isfinite(base["slope"])), base
    # The check table: the secant between two re-solved optima and the tangent's miss, as defined.
    # (Fast mode's small problem may leave every slope undefined, and the table empty.)
    for c in f["checks"]:
        a, b = by_value[(c["theta"], c["lo"])], by_value[(c["theta"], c["hi"])]
        assert c["secant"] == pytest.approx((b["r_soft"] - a["r_soft"]) / (b["value"] - a["value"]))
        assert c["tangent_miss"] == pytest.approx(a["r_soft"] + a["slope"] * (b["value"] - a["value"]) - b["r_soft"])
