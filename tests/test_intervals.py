"""Intervals on E from the scene sample (`diffsense.metrics.bootstrap_ci`, `difference_ci`) and
result.json's interval keys.

- The reweighting bootstrap is E of the resampled scene set: each resample's E, read off the
  per-variant sums of one evaluation, equals E_ref (or E_hard) evaluated afresh through the
  pipeline on that resample's variants (`with_variants`), to 1e-9 in float64.
- Variants identical within each scenario give an interval that collapses to the point; one
  variant per scenario gives none (None, and result.json's null with a note).
- Paired, the difference between the main job's best step and the next is resampled scene by
  scene, and its interval is narrower than the unpaired one.
- Same seed, same interval, bit for bit; another seed, other resamples.
- result.json's keys (stored from a real run in tests/golden/, which `test_golden_results`
  reproduces) and the printed table's interval column and verdict line.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import diffsense as ds
from diffsense.metrics import (
    EstimatorConfig,
    SceneSums,
    argmin_ci,
    bootstrap_ci,
    bootstrap_counts,
    difference_ci,
    estimable,
    with_variants,
)
from diffsense.solve import Evaluator
from diffsense.study import modality_comparisons, with_modality_comparisons
from tests._laws import THRESHOLD
from tests.test_cli_optimise import _line, _main, _Solved

GOLDEN = Path(__file__).parent / "golden"


@pytest.fixture(scope="module", params=["physical", "threshold"])
def small(request):
    """The main job's problem made small: radar HFOV over sc01 + sc03, 3 variants each, its
    reference on 4 detection draws under the physical law, E_hard under the threshold law."""
    law = {} if request.param == "physical" else {"sensor_config": THRESHOLD["radar"]}
    E = ds.objective(ds.Problem(scenarios=["sc01", "sc03"], variants=3, seed=0,
                                estimator=EstimatorConfig(reference_draws=4), **law))
    ev = Evaluator(E)
    return E, ev, np.asarray(E.data.scenario)


def test_each_resample_s_e_is_e_of_the_resampled_scene_set(small):
    E, ev, strata = small
    sums = ev.scene_sums(30.0)
    n = strata.size
    assert sums.e(np.ones((1, n)))[0] == pytest.approx(ev.e_reference(30.0), abs=1e-9)
    counts = bootstrap_counts(strata, resamples=3, seed=7)
    # within each scenario, as many draws as it holds variants
    assert np.all([counts[:, strata == s].sum(axis=1) == 3 for s in (0, 1)])
    for c in counts:
        resampled = with_variants(E, np.repeat(np.arange(n), c))
        direct = Evaluator(resampled).e_reference(30.0)  # the pipeline, afresh, on the resample
        assert sums.e(c[None])[0] == pytest.approx(direct, abs=1e-9)


def test_variants_identical_within_each_scenario_collapse_the_interval_to_the_point(small):
    E, _, strata = small
    same = with_variants(E, [0, 0, 0, 3, 3, 3])  # each scenario's first variant three times
    ev = Evaluator(same)
    lo, hi = bootstrap_ci(ev.scene_sums(30.0), strata)
    assert lo == pytest.approx(ev.e_reference(30.0), abs=1e-12) and hi == pytest.approx(lo, abs=1e-12)


def test_one_variant_per_scenario_has_no_interval(small):
    E, _, _ = small
    one = with_variants(E, [0, 3])
    sums, strata = Evaluator(one).scene_sums(30.0), np.array([0, 1])
    assert not estimable(strata) and bootstrap_counts(strata) is None
    assert bootstrap_ci(sums, strata) is None and difference_ci(sums, sums, strata) is None
    assert estimable(np.zeros(2)) and not estimable(np.array([0, 0, 1]))  # one stratum of one is enough to refuse


def test_the_paired_difference_s_interval_is_narrower_than_the_unpaired(small):
    # Two neighbouring steps, 90 and 120 deg: each scene's error moves little from one to the
    # other, so pairing cancels what the scenes share (at 30 deg the radar's regime changes, and
    # the scenes' changes differ by as much as the scenes do: there pairing gains little).
    _, ev, strata = small
    a, b = ev.scene_sums(120.0), ev.scene_sums(90.0)
    paired = difference_ci(a, b, strata)
    unpaired = difference_ci(a, b, strata, paired=False)
    diff = ev.e_reference(120.0) - ev.e_reference(90.0)
    assert paired[0] <= diff <= paired[1] and unpaired[0] <= diff <= unpaired[1]
    assert paired[1] - paired[0] < 0.5 * (unpaired[1] - unpaired[0])


def test_same_seed_same_interval_bit_for_bit_and_another_seed_other_resamples(small):
    _, ev, strata = small
    sums = ev.scene_sums(60.0)
    assert bootstrap_ci(sums, strata, seed=3) == bootstrap_ci(sums, strata, seed=3)
    # (three variants a scenario allow few distinct resamples: the quantiles may well coincide)
    assert np.array_equal(bootstrap_counts(strata, seed=3), bootstrap_counts(strata, seed=3))
    assert not np.array_equal(bootstrap_counts(strata, seed=3), bootstrap_counts(strata, seed=4))
    lo, hi = bootstrap_ci(sums, strata, level=0.5, seed=3)
    wide = bootstrap_ci(sums, strata, level=0.99, seed=3)
    assert wide[0] <= lo <= ev.e_reference(60.0) <= hi <= wide[1]
    with pytest.raises(ValueError):
        bootstrap_ci(sums, strata, level=1.0)


def test_padding_is_never_drawn_and_the_tracked_question_reweights_per_draw():
    weight = np.array([1.0, 1.0, 1.0, 1.0, 0.0])
    counts = bootstrap_counts(np.array([0, 0, 1, 1, 1]), weight=weight, resamples=50, seed=0)
    assert np.all(counts[:, 4] == 0) and np.all(counts[:, :2].sum(axis=1) == 2)
    # two draws of one variant: J is the mean of the draws' J, not J of their mean
    sums = SceneSums(sq=np.array([2.0]), instants=np.array([2.0]), tracked_sq=np.array([[4.0], [0.0]]),
                     tracked=np.array([[1.0], [0.0]]), question="tracked", miss_penalty_m2=10.0)
    assert sums.e2(np.ones((1, 1)))[0] == pytest.approx(np.mean([4.0 / 2.0 + 10.0 * 0.5, 0.0 + 10.0]))


def test_result_json_carries_the_intervals_a_real_run_stored():
    """The line golden: sc01 + sc04, 2 variants each, the threshold law (a real run, reproduced bit
    for bit by test_golden_results)."""
    result = json.loads((GOLDEN / "line_result.json").read_text())
    assert result["ci_level"] == 0.9 and result["ci_method"]["resamples"] > 0
    steps = [p["r"] for p in result["sweep"]]
    lo, hi = result["E_ci"]
    assert lo <= result["E_hard_star"] <= hi
    for p in result["sweep"]:
        assert p["E_ci"][0] <= p["E_hard"] <= p["E_ci"][1]
    best = min(result["sweep"], key=lambda p: p["E_hard"])
    against = [c for c in result["comparisons"] if c["b"] == f"{best['r']:.5g} deg"]
    assert len(against) >= len(steps) - 1
    for c in result["comparisons"]:
        assert set(c) == {"a", "b", "diff_m", "ci", "ci_unpaired", "paired", "of", "verdict"} and c["of"] == "sweep"
        assert c["ci"][0] <= c["ci"][1] and c["ci_unpaired"][0] <= c["ci_unpaired"][1] and c["verdict"]
    same = result["near_optimal"]["indistinguishable"]
    assert best["r"] in same and set(same) <= set(steps)
    box = json.loads((GOLDEN / "box_result.json").read_text())  # one variant: no interval, a note why
    assert box["E_ci"] is None and box["ci_method"]["note"] and box["r_star_ci"] is None
    (default,) = box["comparisons"]  # r* against the default suite, its difference without an interval
    assert default["of"] == "default" and default["ci"] is None and default["diff_m"] < 0


def _with_intervals(sensor: str, e: float) -> dict:
    out = _line(sensor, e)
    out["sweep"][0]["E_ci"], out["sweep"][1]["E_ci"] = [e + 0.5, e + 1.5], [e + 1.25, e + 2.75]
    verdict = "180 deg is worse than 30 deg by 1.00 m [0.25, 1.75]"
    return out | {"ci_level": 0.9, "E_ci": [e - 0.5, e + 0.5], "ci_method": {"resamples": 2000, "note": None},
                  "comparisons": [{"a": "180 deg", "b": "30 deg", "diff_m": 1.0, "ci": [0.25, 1.75],
                                   "ci_unpaired": [-0.5, 2.5], "paired": True, "verdict": verdict}]}


def test_the_printed_table_shows_each_interval_and_the_verdicts(tmp_path, capsys, monkeypatch):
    # the command line's own path (tests/test_cli_optimise.py), with a result that holds intervals
    monkeypatch.setattr(ds, "optimise", lambda problem, **kw: _Solved(_with_intervals("radar", 3.0)))
    code, out, _ = _main(["--sensor", "radar", "--out", str(tmp_path / "o"), "--quiet"], capsys)
    assert code == 0 and "[3.50, 4.50]" in out and "[2.50, 3.50]" in out
    assert "180 deg is worse than 30 deg by 1.00 m [0.25, 1.75]" in out
    none = _with_intervals("radar", 3.0) | {"E_ci": None, "comparisons": [],
                                            "ci_method": {"note": "one variant per scenario"}}
    none["sweep"][0]["E_ci"] = none["sweep"][1]["E_ci"] = None
    monkeypatch.setattr(ds, "optimise", lambda problem, **kw: _Solved(none))
    code, out, _ = _main(["--sensor", "radar", "--out", str(tmp_path / "p"), "--quiet"], capsys)
    assert code == 0 and "one variant per scenario" in out and "[3.50" not in out and "worse than" not in out



@dataclasses.dataclass(frozen=True)
class _Answer:
    """The fields of a `diffsense.Result` that a sensor-against-sensor comparison reads."""
    sensor: str
    param: str
    r_star: dict
    units: dict
    E_hard_star: float
    reference: dict
    intervals: dict[str, Any]


def _sums(per_variant_sq) -> SceneSums:
    sq = np.asarray(per_variant_sq, np.float64)
    return SceneSums(sq=sq, instants=np.ones_like(sq), tracked_sq=sq[None], tracked=np.ones_like(sq)[None])


def test_r_star_s_interval_is_the_argmin_re_picked_on_each_resample():
    strata = np.array([0, 0, 0, 1, 1, 1])
    # 20 is best on every variant: every resample picks it
    clear = [_sums([4, 4, 4, 9, 9, 9]), _sums([1, 1, 1, 2, 2, 2]), _sums([3, 3, 3, 5, 5, 5])]
    assert argmin_ci([10.0, 20.0, 30.0], clear, strata) == (20.0, 20.0)
    # each scenario's first variant favours 10, the others 20: resamples split between the two
    split = [_sums([0, 3, 3, 0, 3, 3]), _sums([2.2, 1, 1, 2.2, 1, 1]), _sums([9] * 6)]
    counts = bootstrap_counts(strata, seed=0)
    picks = np.where(np.stack([s.e2(counts) for s in split[:2]]).argmin(axis=0) == 0, 10.0, 20.0)
    assert set(np.unique(picks)) == {10.0, 20.0}  # the resamples do disagree
    assert argmin_ci([10.0, 20.0, 30.0], split, strata) == (10.0, 20.0)  # ends at evaluated points, never 30
    assert argmin_ci([10.0], [_sums([1.0, 2.0])], np.array([0, 1])) is None  # one variant per scenario
    with pytest.raises(ValueError):
        argmin_ci([10.0, 20.0], clear, strata)


def test_result_json_s_r_star_interval_holds_r_star_at_evaluated_points():
    result = json.loads((GOLDEN / "line_result.json").read_text())
    (name, (lo, hi)), = result["r_star_ci"].items()
    assert name == result["param"] and lo <= result["r_star"][name] <= hi
    assert result["interval"][0] <= lo and hi <= result["interval"][1]
    assert result["ci_method"]["r_star_points"] >= len(result["sweep"])
    # made dense where the picks fall: 1 % of the interval apart, or a quarter of r*'s interval
    wanted = max(0.01 * (result["interval"][1] - result["interval"][0]), 0.25 * (hi - lo))
    assert 0 < result["ci_method"]["r_star_resolution"] <= wanted
    # chosen on E_hard (the threshold law): the interval says it is a lower bound
    assert result["reference"]["answer_on"] == "E_hard" and result["ci_method"]["r_star_caveat"]


def test_sensor_against_sensor_is_paired_over_the_shared_scenes(small):
    """`modality_comparisons` on two answers over the same variants (here one objective at two r
    standing for two sensors: the machinery is the same): the paired difference of the sums,
    its interval beside the unpaired one, and nothing for answers over other scenes."""
    _, ev, strata = small

    def answer(sensor, r):
        return _Answer(sensor=sensor, param="hfov_deg", r_star={"hfov_deg": r}, units={"hfov_deg": "deg"},
                       E_hard_star=ev.e_hard(r), reference={"answer_on": "E_ref", "E_ref_star": ev.e_reference(r)},
                       intervals={"answer_sums": ev.scene_sums(r), "strata": strata, "ci_method": {"seed": 0},
                                  "comparisons": []})

    a, b = answer("radar", 120.0), answer("camera", 30.0)
    (c,) = modality_comparisons({"radar": a, "camera": b})
    assert (c["a"], c["b"], c["of"]) == ("radar at 120 deg", "camera at 30 deg", "sensors")
    assert c["diff_m"] == pytest.approx(ev.e_reference(120.0) - ev.e_reference(30.0), abs=1e-12)
    assert tuple(c["ci"]) == difference_ci(ev.scene_sums(120.0), ev.scene_sums(30.0), strata)
    assert tuple(c["ci_unpaired"]) == difference_ci(ev.scene_sums(120.0), ev.scene_sums(30.0), strata, paired=False)
    assert c["ci"][0] <= c["diff_m"] <= c["ci"][1]
    other = answer("camera", 30.0)
    other = dataclasses.replace(other, intervals=dict(other.intervals, strata=np.zeros_like(strata)))  # other scenes
    assert modality_comparisons({"radar": a, "camera": other}) == []
    both = with_modality_comparisons({"radar": a, "camera": b})
    assert [x["comparisons"] for x in (both["radar"].intervals, both["camera"].intervals)] == [[c], [c]]
