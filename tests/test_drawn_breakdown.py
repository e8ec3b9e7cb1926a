"""The breakdown of E_ref over its detection draws (`Evaluator.breakdown`, result.json's
"breakdown_of" "E_ref"): under a probabilistic law the parts the job reports are those of the
value the answer is chosen on, not of E_hard at median detections.

- Pooled, it is E_ref itself (`Objective.reference`), and its parts add up to it: the shares of
  the scenarios and of the coverage parts weigh their E_ref^2 into the pooled E_ref^2.
- The "tracked" question's J over the draws is that question's own E_ref^2.
- A scenario's part equals E_ref of a problem of that scenario alone (the same scenes and draws):
  an independent evaluation, not a re-reading of the same arrays.
- Under the threshold law the breakdown is of E_hard, unchanged.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import diffsense as ds
from diffsense.metrics import EstimatorConfig
from diffsense.solve import Evaluator
from tests._toy_pipeline import THRESHOLD_RADAR, radar_objective

R = 6.0  # hfov_deg where the toy radar sees its target now and then: every coverage part is drawn


@pytest.fixture(scope="module")
def toy():
    E = radar_objective(draws=6, n=3)
    ev = Evaluator(E)
    return E, ev, ev.breakdown(R)


def test_pooled_it_is_e_ref_and_its_parts_add_up_to_it(toy):
    E, ev, b = toy
    e_ref = float(E.reference(E.point(R)).e)
    assert b["E_ref"] == pytest.approx(e_ref, rel=1e-9) and b["E_ref"] == pytest.approx(ev.e_reference(R), rel=1e-12)
    assert "E_hard" not in b and b["by_horizon"]["E_ref"]
    parts = b["coverage"]["parts"]
    assert sum(p["share"] for p in parts.values()) == pytest.approx(1.0)
    assert sum(p["share"] * (p["E_ref"] or 0.0) ** 2 for p in parts.values()) == pytest.approx(e_ref**2, rel=1e-9)
    # the shares are expectations over the draws, every part drawn; E_hard at median detections
    # is another value with other parts
    assert all(0.0 < p["share"] < 1.0 for p in parts.values())
    hard = ev.breakdown(R, of_reference=False)
    assert abs(hard["E_hard"] - e_ref) > 0.01 * e_ref
    # the horizon steps average to it as well (Eq. 12 is the mean over steps)
    assert np.mean(np.square(b["by_horizon"]["E_ref"])) == pytest.approx(e_ref**2, rel=1e-9)
    # scenario shares: each toy scenario's variants hold equal instants, weights 1
    scenario = np.asarray(E.data.scenario)
    shares = {name: np.mean(scenario == k) for k, name in enumerate(E.scenario_names)}
    assert sum(shares[n] * p["E_ref"] ** 2 for n, p in b["by_scenario"].items()) == pytest.approx(e_ref**2, rel=1e-9)


def test_the_tracked_questions_j_over_the_draws_is_its_own_e_ref_squared(toy):
    E, ev, b = toy
    tracked = dataclasses.replace(E, question="tracked")
    j = float(tracked.reference(tracked.point(R)).e2)
    assert b["tracked"]["J_m2"] == pytest.approx(j, rel=1e-9)
    assert b["tracked"]["miss_penalty_m2"] == float(E.miss_penalty_m2)


def test_under_the_threshold_law_it_is_the_hard_breakdown():
    ev = Evaluator(radar_objective(radar=THRESHOLD_RADAR, n=2))
    b = ev.breakdown(R)
    assert "E_ref" not in b and b["E_hard"] == pytest.approx(ev.e_hard(R), rel=1e-12)
    assert ev.breakdown(R, of_reference=False) == b


def test_a_scenarios_part_is_e_ref_of_that_scenario_alone():
    def problem(scenarios):
        return ds.Problem(sensor="radar", params={"hfov_deg": (5.0, 60.0)}, scenarios=scenarios, variants=1, seed=0,
                          estimator=EstimatorConfig(reference_draws=4))

    both = Evaluator(ds.objective(problem(["sc01", "sc03"]))).breakdown(20.0)
    alone = Evaluator(ds.objective(problem(["sc01"])))  # first in both lists: the same scenes and draws
    # rel 1e-6: the CS-LSTM predicts in float32, and a batch of other size rounds otherwise
    assert both["by_scenario"]["sc01"]["E_ref"] == pytest.approx(alone.e_reference(20.0), rel=1e-6)
    assert both["by_scenario"]["sc01"]["E_ref"] != pytest.approx(both["E_ref"], rel=1e-3)
