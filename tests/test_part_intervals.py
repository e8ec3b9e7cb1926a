"""Intervals on the breakdown's parts and on the judged value (`diffsense.metrics.part_cis`).

- Each part's reweighted E is that part of the breakdown of the resampled scene set, evaluated
  afresh through the pipeline (`with_variants`), to 1e-9 in float64: a scenario's part, each
  coverage part and each horizon step's E; with every count 1 it is the breakdown's own value.
- Every part's interval holds the part's value; variants identical within each scenario collapse
  it to the point; one variant per scenario gives none.
- result.json's judged value carries its interval from the judging seed's scene sample.
- A many-parameter answer's interval, and its paired comparison with the default suite.
"""

from __future__ import annotations

import numpy as np
import pytest

import diffsense as ds
from diffsense.metrics import (
    EstimatorConfig,
    bootstrap_ci,
    bootstrap_counts,
    difference_ci,
    part_cis,
    with_part_cis,
    with_variants,
)
from diffsense.solve import Evaluator, SolveConfig
from diffsense.study import box_intervals


@pytest.fixture(scope="module")
def small():
    """Radar HFOV over sc01 + sc03, 3 variants each, E_ref on 4 detection draws (physical law)."""
    E = ds.objective(ds.Problem(scenarios=["sc01", "sc03"], variants=3, seed=0,
                                estimator=EstimatorConfig(reference_draws=4)))
    return E, Evaluator(E), np.asarray(E.data.scenario), np.asarray(E.data.weight)


def _values(breakdown: dict) -> dict:
    """Each part's E in the layout of `PartSums.names`."""
    key = "E_ref" if "E_ref" in breakdown else "E_hard"
    out = {("by_scenario", n): v[key] for n, v in breakdown["by_scenario"].items()}
    out |= {("coverage", n): v[key] for n, v in breakdown["coverage"]["parts"].items()}
    return out | {("by_horizon", f): v for f, v in enumerate(breakdown["by_horizon"][key])}


def test_each_part_reweighted_is_that_part_of_the_resampled_scene_set(small):
    E, ev, strata, _ = small
    r = 60.0
    parts = ev.part_sums(r)
    own = _values(ev.breakdown(r))
    at_one = parts.e(np.ones((1, strata.size)))[:, 0]
    for name, e in zip(parts.names, at_one):
        if own[name] is None:
            assert np.isnan(e)
        else:
            assert e == pytest.approx(own[name], abs=1e-9)
    for c in bootstrap_counts(strata, resamples=3, seed=5):
        direct = _values(Evaluator(with_variants(E, np.repeat(np.arange(strata.size), c))).breakdown(r))
        for name, e in zip(parts.names, parts.e(c[None])[:, 0]):
            if direct[name] is None:
                assert np.isnan(e)
            else:
                assert e == pytest.approx(direct[name], abs=1e-9), name


def test_every_part_s_interval_holds_its_value_and_collapses_without_spread(small):
    E, ev, strata, weight = small
    r = 60.0
    breakdown = ev.breakdown(r)
    cis = part_cis(ev.part_sums(r), strata, weight)
    out = with_part_cis(breakdown, ev.part_sums(r), cis)
    for name, value in _values(breakdown).items():
        where, part = name
        ci = (out["by_scenario"][part]["E_ci"] if where == "by_scenario" else
              out["coverage"]["parts"][part]["E_ci"] if where == "coverage" else out["by_horizon"]["E_ci"][part])
        if value is not None:
            assert ci[0] <= value + 1e-12 and value <= ci[1] + 1e-12
    assert out["by_scenario"]["sc01"]["E_ci"][1] > out["by_scenario"]["sc01"]["E_ci"][0]
    same = Evaluator(with_variants(E, [0, 0, 0, 3, 3, 3]))
    collapsed = part_cis(same.part_sums(r), strata, weight)
    values = _values(same.breakdown(r))
    for name, ci in zip(same.part_sums(r).names, collapsed):
        if values[name] is not None:
            assert ci == pytest.approx([values[name]] * 2, abs=1e-9)
    one = Evaluator(with_variants(E, [0, 3]))
    assert part_cis(one.part_sums(r), np.array([0, 1]), np.ones(2)) == [None] * len(one.part_sums(r).names)


def test_a_run_s_judged_value_and_breakdown_carry_their_intervals(small):
    E, _, _, _ = small
    problem = ds.Problem(scenarios=["sc01", "sc03"], variants=3, seed=0, estimator=EstimatorConfig(reference_draws=4),
                         params={"hfov_deg": (30.0, 180.0)}, steps=(30.0, 90.0, 180.0),
                         solve=SolveConfig(max_evaluations=9))
    out = ds.optimise(problem, E=E, figures=False, judge=True).to_json()
    judged = out["judged"]
    assert judged["E_ci"][0] <= judged["E_ref"] <= judged["E_ci"][1]
    for name, part in out["by_scenario"].items():
        assert part["E_ci"][0] <= part["E_ref"] <= part["E_ci"][1], name
    assert len(out["by_horizon"]["E_ci"]) == len(out["by_horizon"]["t_s"])


def test_a_many_parameter_answer_s_interval_and_its_comparison_with_the_default_suite(small):
    _, ev, strata, _ = small
    x, default = np.array([60.0]), np.array([120.0])
    out = box_intervals(ev, x, default, of_reference=True, seed=0)
    assert tuple(out["E_ci"]) == bootstrap_ci(ev.scene_sums(x), strata)
    (c,) = out["comparisons"]
    assert (c["a"], c["b"], c["of"]) == ("r*", "the default suite", "default")
    assert c["diff_m"] == pytest.approx(ev.e_reference(x) - ev.e_reference(default), abs=1e-12)
    assert tuple(c["ci"]) == difference_ci(ev.scene_sums(x), ev.scene_sums(default), strata)
    assert out["r_star_ci"] is None
