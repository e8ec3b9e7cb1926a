"""The one-parameter main job, `ds.optimise`, on the toy pipeline (one tiny scene, three instants):
the evaluations it plans, how the solve is wired into its Result and result.json's "config", the
notes it ends with, the progress events, and which E the answer is judged on."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

import diffsense as ds
from diffsense.metrics import EstimatorConfig, make_objective
from diffsense.solve import SolveConfig, default_steps
from diffsense.study import domain_note, planned_evaluations, problem_config
from diffsense.tracks import prediction_frames
from tests._laws import THRESHOLD
from tests._toy_pipeline import (
    TOY_GAIN,
    ToyPredictor,
    ValidatedToyPredictor,
    toy_scenes,
)
from tests.test_reference import radar_objective

H = "hfov_deg"
SWERLING1 = "configs/sensors/laws/radar_swerling1.toml"


def test_the_planned_evaluations_count_the_sweep_twice_the_budget_the_answer_curves_and_dense_grid():
    refine = 2 * 8  # r*'s interval: at most two rounds of eight points
    assert planned_evaluations(ds.Problem()) == 2 * 6 + 20 + 2 + refine  # steps 30, 60, ..., 180
    assert planned_evaluations(ds.Problem(), sweep_soft=False) == 6 + 20 + 2 + refine
    problem = ds.Problem(steps=[30, 60, 90], extra_curve_points=5, dense_check=10.0,
                         solve=SolveConfig(max_evaluations=12))
    assert planned_evaluations(problem) == 2 * 3 + 12 + 2 + 2 * 5 + (150 // 10 + 1) + refine
    # 70 / 0.7 is 100.00000000000001 in floats: still 100 steps, 101 points
    assert planned_evaluations(ds.Problem(params={"hfov": (30, 100)}, steps=[30, 100], dense_check=0.7)) == \
        2 * 2 + 20 + 2 + 101 + refine


def test_the_recorded_config_is_every_keyword_the_sensor_and_predictor_by_name():
    config = problem_config(ds.Problem(params={"hfov": (30, 90)}, variants=3))  # tests/golden/ holds two whole
    assert list(config) == list(ds.Problem().keywords()) and config["variants"] == 3 and config["weather"] is None
    assert config["sensor"] == "radar" and config["params"] == {H: [30.0, 90.0]} and config["estimator"]["kind"] == "auto"
    suite = ds.Problem(sensor=[ds.sensors.make_sensor("radar"), "camera"], params={"camera.hfov": (30, 60)},
                       predictor=ToyPredictor(jnp.asarray(TOY_GAIN)))
    config = problem_config(suite)
    assert config["sensor"] == ["radar", "camera"] and config["predictor"] == "ToyPredictor"
    assert config["params"] == {"camera.hfov_deg": [30.0, 60.0]}


def _toy_objective(problem, predictor):
    scenes, scenario = toy_scenes(1)
    frames = prediction_frames(scenes.num_frames)[:3]
    return make_objective(scenes, scenario, frames, problem.sensing.built, predictor, names=(H,), shard=False)


@pytest.fixture(scope="module")
def solved():
    problem = ds.Problem(params={H: (20.0, 100.0)}, steps=(20.0, 60.0, 100.0), dense_check=40.0, extra_curve_points=4,
                         solve=SolveConfig(max_evaluations=9), scenarios=["sc01"], sensor_config=THRESHOLD["radar"])
    E = _toy_objective(problem, ValidatedToyPredictor(jnp.asarray(TOY_GAIN)))
    lines, events = [], []
    result = ds.optimise(problem, E=E, progress=lines.append, on_evaluation=events.append, sensitivity=("rain_mm_h",))
    return problem, E, result, lines, events


def test_a_one_parameter_solve_is_wired_into_its_result(solved):
    problem, _, result, _, _ = solved
    s = result.solve
    assert result.r_star == {H: s.r_star} and type(result.r_star[H]) is float
    assert result.E_hard_star == s.E_hard_star and result.E_soft_star == s.E_soft_star
    assert result.params == {H: (20.0, 100.0)} and result.units == {H: "deg"} and result.sensor == "radar"
    assert [p.r for p in s.sweep] == [20.0, 60.0, 100.0] and result.scenarios == ("scenario0",)
    assert result.config == problem_config(problem) and result.reference["answer_on"] == "E_hard"
    assert result.curves is not None and list(result.curves.r) == sorted(result.curves.r)
    assert set(result.wall_s) == {"compile", "run", "programs_compiled", "programs_lowered"}
    assert result.near_optimal["intervals"] and result.flags == tuple(result.to_json()["flags"])


def test_the_dense_check_and_the_domain_note_end_the_notes(solved):
    _, _, result, lines, _ = solved
    assert result.dense_check["step"] == 40.0 and result.dense_check["evaluations"] == 3  # 20, 60, 100
    assert result.domain["validation_rmse_m"] == (0.01, 0.02, 0.03, 0.04, 0.05)
    assert result.domain["outside"] == ["scenario0"]
    solve_notes = [n for n in result.notes if not n.startswith("sensitivity to")]  # the sensitivity's follow
    assert tuple(solve_notes[-2:]) == ("dense check: " + result.dense_check["verdict"], domain_note(result.domain))
    assert "warning: " + domain_note(result.domain) in lines


def test_the_sensitivity_asked_for_is_the_answers(solved):
    problem, E, result, _, _ = solved
    assert result.sensitivity == ds.sensitivity(problem, result, ["rain_mm_h"], E=E)
    assert list(result.sensitivity) == ["rain_mm_h"] and list(result.sensitivity["rain_mm_h"]) == [H]


def test_progress_events_count_every_program_against_the_plan(solved):
    problem, _, result, _, events = solved
    assert all(e["planned"] == planned_evaluations(problem) for e in events)
    assert [e["done"] for e in events] == list(range(1, len(events) + 1))
    solve_runs, figures = result.programs_run["solve"], result.programs_run["figures"]
    assert sum(solve_runs.values()) + sum(figures.values()) == len(events) and sum(figures.values()) > 0
    assert solve_runs["soft"] >= result.solve.evaluations["gradient"]  # the solver's gradients are the evaluator's


def test_an_unknown_odd_parameter_is_refused_before_any_work():
    with pytest.raises(ds.InputError, match="no sensitivity to 'snow'"):
        ds.optimise(ds.Problem(predictor=object()), sensitivity=("snow",))


def test_the_hard_estimator_searches_the_steps_it_is_given():
    problem = ds.Problem(params={H: (20.0, 100.0)}, steps=(20.0, 45.0, 100.0), estimator="hard",
                         solve=SolveConfig(max_evaluations=9), scenarios=["sc01"])
    result = ds.optimise(problem, E=_toy_objective(problem, ToyPredictor(jnp.asarray(TOY_GAIN))), figures=False)
    assert [p.r for p in result.solve.sweep] == [20.0, 45.0, 100.0]
    assert result.solve.evaluations["objective"] <= 9 and result.reference["answer_on"] == "E_hard"


def _swerling(**changes):
    return ds.Problem(**{"params": {H: (20.0, 100.0)}, "steps": (20.0, 60.0, 100.0), "sensor_config": SWERLING1,
                         "estimator": EstimatorConfig(reference_draws=4), "solve": SolveConfig(max_evaluations=9),
                         "scenarios": ["sc01"]} | changes)


def test_under_a_probabilistic_law_the_near_optimal_set_is_judged_on_e_ref():
    # radar_objective: the Swerling I radar on one toy scene, three instants
    result = ds.optimise(_swerling(), E=radar_objective(kind="auto", draws=4), figures=False)
    assert result.reference["answer_on"] == "E_ref"
    # the tolerance is 0.5 % of the best E_ref evaluated, which is r*'s (the answer is chosen on it)
    assert result.near_optimal["tolerance_m"] == pytest.approx(0.005 * result.reference["E_ref_star"], rel=1e-12)


SECANT = SolveConfig(method="secant", max_evaluations=9)  # the gradient continuation, not Brent


def test_under_straight_through_the_sweep_reads_e_soft_off_e_ref_and_every_value_is_a_candidate():
    problem = _swerling(solve=SECANT)
    E, events = radar_objective(kind="auto", draws=4), []
    assert E.estimator_kind == "straight-through"
    result = ds.optimise(problem, E=E, figures=False, on_evaluation=events.append)
    # the sweep: one E_ref program per step, no value-and-gradient; E_soft is that E_ref
    assert [e["kind"] for e in events[:3]] == ["reference"] * 3
    assert [p.E_soft for p in result.solve.sweep] == [p.E_hard for p in result.solve.sweep]
    assert [p.E_hard for p in result.solve.sweep] == [e["E_m"] for e in events[:3]]
    assert [e["done"] for e in events] == list(range(1, len(events) + 1))
    assert {e["planned"] for e in events} == {planned_evaluations(problem, sweep_soft=False)}
    # every value a gradient evaluation saw is an answer candidate: the answer is the best E_ref seen
    assert result.solve.E_hard_star == min(e["E_m"] for e in events if e["kind"] == "reference")


def test_under_straight_through_the_figures_draw_the_slope_where_the_solve_evaluated_it():
    # E_soft's value is E_ref: the figures read it off the sweep's E_ref, and draw dE/dr at the
    # points the solve evaluated it, without a value-and-gradient program of their own
    problem, events = _swerling(solve=SECANT), []
    result = ds.optimise(problem, E=radar_objective(kind="auto", draws=4), on_evaluation=events.append)
    assert {e["planned"] for e in events} == {planned_evaluations(problem, sweep_soft=False)}
    assert result.programs_run["figures"]["soft"] == 0
    curves = result.curves
    sweep = {p.r: p.E_hard for p in result.solve.sweep}  # E_ref at the steps
    for r, e, slope in zip(curves.r, curves.E_soft, curves.dE_dr):
        if r in sweep:
            assert e == pytest.approx(sweep[r], rel=1e-12)
        assert np.isfinite(slope) or r in sweep
    assert np.isfinite(curves.dE_dr).any()  # the final level's gradient evaluations


def test_under_straight_through_the_default_steps_are_swept():
    result = ds.optimise(_swerling(steps=None), E=radar_objective(kind="auto", draws=4), figures=False)
    assert [p.r for p in result.solve.sweep] == list(default_steps(20.0, 100.0))  # 20, 36, ..., 100


def test_under_a_probabilistic_law_the_answer_is_searched_on_e_ref_values_alone():
    # method "auto": Brent on E_ref inside the best step's bracket, no gradient program at all
    problem, events = _swerling(), []
    result = ds.optimise(problem, E=radar_objective(kind="auto", draws=4), figures=False, on_evaluation=events.append)
    assert "soft" not in {e["kind"] for e in events}  # the breakdowns' hard programs follow the answer
    assert result.programs_run["solve"]["soft"] == 0
    assert result.solve.evaluations["gradient"] == 0 and result.solve.evaluations["objective"] <= 9
    assert result.reference["E_ref_star"] == min(e["E_m"] for e in events if e["kind"] == "reference")
    assert {e["planned"] for e in events} == {planned_evaluations(problem, sweep_soft=False)}
    assert result.config["solve"]["method"] == "auto"
