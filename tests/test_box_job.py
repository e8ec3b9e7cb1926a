"""The many-parameter main job (a box solve of J = E + lambda * cost, and the Pareto front by a sweep
of lambda): the cost weights a front accepts, the front's order and pareto.json, the Result a box
solve returns, which E an answer is judged on, how a design is priced; on the toy pipeline (one
tiny scene), and a suite end to end through the shipped predictor's network."""

from __future__ import annotations

import math
from pathlib import Path

import jax
import numpy as np
import pytest

import diffsense as ds
from diffsense.metrics import make_objective
from diffsense.solve import BoxConfig
from diffsense.study import ParetoFront, check_lambdas, domain_note
from diffsense.tracks import prediction_frames
from tests._laws import THRESHOLD
from tests._toy_pipeline import (
    TOY_GAIN,
    ToyPredictor,
    ValidatedToyPredictor,
    toy_scenes,
)
from tests.test_result_json import _box

ROOT = Path(__file__).resolve().parents[1]
PARAMS = {"radar.range_m": (30.0, 200.0), "camera.width_px": (640.0, 3840.0)}
THRESHOLDS = dict(THRESHOLD)  # both members on the threshold law: answers on E_hard
SWERLING = {"radar": "configs/sensors/laws/radar_swerling1.toml", "camera": THRESHOLD["camera"]}
TINY = BoxConfig(samples=4, starts=1, tau_schedule=(1.0,), max_steps=2, max_soft=3)


def _problem(**changes) -> ds.Problem:
    return ds.Problem(**{"sensor": ["radar", "camera"], "params": PARAMS, "scenarios": ["sc01"],
                         "sensor_config": THRESHOLDS} | changes)


def _toy_objective(problem, predictor=None):
    scenes, scenario = toy_scenes(1)
    frames = prediction_frames(scenes.num_frames)[:3]
    predictor = ToyPredictor(jax.numpy.asarray(TOY_GAIN)) if predictor is None else predictor
    return make_objective(scenes, scenario, frames, problem.sensing.built, predictor,
                          names=tuple(problem.params), key=jax.random.key(2, impl="rbg"))


def test_cost_weights_are_sorted_floats():
    assert check_lambdas([0.05, 0, 0.01]) == (0.0, 0.01, 0.05)
    assert all(type(v) is float for v in check_lambdas([0, 1]))


@pytest.mark.parametrize("lambdas, culprit", [
    *((bad, "at least two cost weights >= 0") for bad in ([], [0.01], [0.0, -0.01], [0.0, math.nan], [0.0, math.inf])),
    ([0.05, 0.02, 0.05, 0.02, 0.1], r"^cost weight 0\.02 is given twice"),  # the smallest repeated one
])
def test_bad_cost_weights_are_refused(lambdas, culprit):
    with pytest.raises(ds.InputError, match=culprit):
        check_lambdas(lambdas)


@pytest.mark.parametrize("judged_on", ["E_hard", "E_ref"])
def test_the_front_cheapest_first_and_pareto_json(judged_on):
    designs = (_box(cost=3.0, E_hard=4.0), _box(cost=1.0, E_hard=6.0), _box(cost=2.0, E_hard=7.0),
               _box(cost=0.5, E_hard=9.0))
    front = ParetoFront(sensor="radar+camera", units={"hfov_deg": "deg"}, currency="EUR", lambdas=(0.0, 0.01, 0.02, 0.05),
                        designs=designs, on_front=(True, True, False, True), cloud=((1.0, 6.0), (3.0, 4.0)),
                        counts={"soft": 20, "hard": 9}, wall_s=12.5, judged_on=judged_on)
    assert front.front() == [3, 1, 0]
    out, key = front.to_dict(), f"{judged_on}_m"
    assert list(out) == ["sensor", "judged_on", "currency", "units", "lambdas", "designs", "front", "evaluations",
                         "wall_s", "cloud"]
    assert (out["sensor"], out["judged_on"], out["currency"], out["units"]) == ("radar+camera", judged_on, "EUR",
                                                                                {"hfov_deg": "deg"})
    assert out["lambdas"] == [0.0, 0.01, 0.02, 0.05] and out["front"] == [3, 1, 0]
    assert out["evaluations"] == {"soft": 20, "hard": 9} and out["wall_s"] == 12.5
    assert out["cloud"] == {"cost": [1.0, 3.0], key: [6.0, 4.0]}
    d = designs[2]
    assert out["designs"][2] == {"lambda": 0.02, "r_star": d.x_star, key: 7.0, "E_soft_m": d.E_soft, "cost": 2.0,
                                 "J": d.J_star, "on_front": False, "on_bound": d.on_bound, "gradient": d.gradient,
                                 "source": d.source, "evaluations": d.counts}


@pytest.fixture(scope="module")
def boxed():
    problem = _problem(box=BoxConfig(samples=4, starts=1, tau_schedule=(2.0, 1.0), max_steps=3, max_soft=6,
                                      bound_tol=0.02), cost_weight=1.0)
    E = _toy_objective(problem, ValidatedToyPredictor(jax.numpy.asarray(TOY_GAIN)))
    events = []
    return problem, ds.optimise(problem, E=E, on_evaluation=events.append), events


def test_a_box_solve_returns_its_answer_in_a_result(boxed):
    problem, result, events = boxed
    box = result.box
    assert result.solve is None and result.sensor == "radar+camera" and result.r_star == box.x_star
    assert result.params == PARAMS and result.units == {"radar.range_m": "m", "camera.width_px": "px"}
    assert result.E_soft_star == box.E_soft and result.E_hard_star == box.E_hard  # the threshold law: E_hard
    assert result.reference["answer_on"] == "E_hard" and result.scenarios == ("scenario0",)
    assert box.cost_weight == 1.0 and result.config == ds.study.problem_config(problem)
    assert result.programs_run["figures"] == {"soft": 0, "hard": 0}
    assert sum(result.programs_run["solve"].values()) >= box.counts["soft"] + box.counts["hard"]
    assert result.breakdown["by_scenario"]["scenario0"]["E_hard"] == pytest.approx(result.E_hard_star, rel=1e-9)
    assert events[0]["planned"] == 6 + 4 and events[0]["done"] == 1  # the soft budget and the sample
    assert all(e["planned"] >= e["done"] for e in events) and all(np.isfinite(e["cost"]) for e in events)


def test_a_parameter_on_its_bound_is_noted(boxed):
    result = boxed[1]  # a cost weight of 1 m per EUR: the cheapest design, both parameters on their lower bounds
    assert result.box.on_bound == {"radar.range_m": "lower", "camera.width_px": "lower"}
    assert result.r_star == {"radar.range_m": 30.0, "camera.width_px": 640.0}
    assert result.domain["outside"] == ["scenario0"]
    assert result.box_notes[-1] == domain_note(result.domain) and len(result.box_notes) == 3
    assert all(n in note for n, note in zip(PARAMS, result.box_notes))
    assert result.notes == result.box_notes and result.on_bound is True


def test_a_cost_weight_makes_one_parameter_a_box_solve():
    problem = ds.Problem(params={"range_m": (30.0, 200.0)}, cost_weight=0.5, box=TINY, scenarios=["sc01"],
                         sensor_config=THRESHOLD["radar"])
    result = ds.optimise(problem, E=_toy_objective(problem))
    assert result.solve is None and result.box.cost_weight == 0.5 and set(result.r_star) == {"range_m"}


def test_a_box_solve_and_a_front_are_seeded_by_the_problem():
    problem = _problem(box=TINY, seed=7)
    E = _toy_objective(problem)
    runs = [ds.optimise(problem.replace(seed=seed), E=E).box for seed in (7, 7, 8)]
    assert runs[0] == runs[1] and runs[0].history != runs[2].history  # the coarse sample is the seed's
    fronts = [ds.pareto(problem.replace(seed=seed), [0.0, 0.01], E=E) for seed in (7, 7)]
    assert fronts[0].designs == fronts[1].designs and fronts[0].lambdas == (0.0, 0.01)


def test_under_a_random_law_answers_are_judged_on_e_ref():
    problem = _problem(sensor_config=SWERLING, box=TINY)
    E = _toy_objective(problem)
    assert ds.optimise(problem, E=E).reference["answer_on"] == "E_ref"
    assert ds.pareto(problem, [0.0, 0.01], E=E).judged_on == "E_ref"
    hard = problem.replace(estimator="hard")
    assert ds.optimise(hard, E=E).reference["answer_on"] == "E_hard"


def _costs_file(tmp_path) -> str:
    """configs/costs.toml in dollars, the radar's base 45 higher."""
    text = (ROOT / "configs" / "costs.toml").read_text()
    assert text.count('currency = "EUR"') == 1 and text.count("base = 45.0") == 1
    path = tmp_path / "costs.toml"
    path.write_text(text.replace('currency = "EUR"', 'currency = "USD"').replace("base = 45.0", "base = 90.0"))
    return str(path)


def test_a_front_is_priced_with_the_problems_cost_model(tmp_path):
    problem = _problem(box=TINY)
    E = _toy_objective(problem)
    default, priced = (ds.pareto(p, [0.0, 0.01], E=E) for p in (problem, problem.replace(costs=_costs_file(tmp_path))))
    assert (default.currency, priced.currency) == ("EUR", "USD") and priced.to_dict()["currency"] == "USD"
    assert priced.designs[0].x_star == default.designs[0].x_star  # lambda 0: the price does not move the answer
    assert priced.designs[0].cost == pytest.approx(default.designs[0].cost + 45.0, rel=1e-12)


@pytest.mark.slow
def test_a_suite_problem_is_optimised_end_to_end():
    problem = ds.Problem(sensor=["radar", "camera"],
                         params={"radar.hfov_deg": (20.0, 120.0), "camera.hfov_deg": (30.0, 120.0)},
                         scenarios=["sc01"], variants=1, prediction_stride_frames=40,
                         predictor=ds.predictors.init_predictor(), box=BoxConfig(max_soft=12, starts=1))
    E = ds.objective(problem)
    grad = jax.grad(lambda r: E(r, tau=2.0))({"radar.hfov_deg": 50.0, "camera.hfov_deg": 60.0})
    assert set(grad) == set(problem.params) and all(np.isfinite(float(v)) for v in grad.values())
    content = ds.optimise(problem, E=E).to_json()
    assert all(lo <= content["r_star"][n] <= hi for n, (lo, hi) in problem.params.items())
    assert content["param"] is None and set(content["box"]["gradient"]) == set(problem.params)
    of = content["breakdown_of"]  # one scenario: its part is the pooled value the answer is chosen on
    assert content["by_scenario"]["sc01"][of] == pytest.approx(content["E_pooled"], rel=1e-9)
