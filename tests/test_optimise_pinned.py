"""The main job's own bookkeeping, pinned: the evaluations it plans, the memory it estimates,
the config it records, the predictor's precision, and how `optimise` wires a
one-parameter solve into its Result (on the toy pipeline: one tiny scene, three instants)."""

from __future__ import annotations

import jax.numpy as jnp
import pytest

import diffsense as ds
from diffsense.study._domain import domain_note
from diffsense.study._optimise import (
    _config,
    _in_dtype,
    memory_estimate_bytes,
    planned_evaluations,
)
from diffsense.metrics import make_objective
from diffsense.predictors import CastPredictor, init_predictor
from diffsense.sensors import make_sensor
from diffsense.solve import SolveConfig
from diffsense.tracks import prediction_frames
from tests._toy_pipeline import (
    TOY_GAIN,
    ToyPredictor,
    ValidatedToyPredictor,
    toy_scenes,
)

H = "hfov_deg"


def test_the_planned_evaluations_count_the_sweep_twice_the_budget_the_answer_curves_and_dense_grid():
    assert planned_evaluations(ds.Problem()) == 2 * 6 + 20 + 2  # steps 30, 60, ..., 180
    assert planned_evaluations(ds.Problem(), sweep_soft=False) == 6 + 20 + 2
    problem = ds.Problem(steps=[30, 60, 90], extra_curve_points=5, dense_check=10.0,
                         solve=SolveConfig(max_evaluations=12))
    assert planned_evaluations(problem) == 2 * 3 + 12 + 2 + 2 * 5 + (150 // 10 + 1)
    # 70 / 0.7 is 100.00000000000001 in floats: still 100 steps, 101 points
    assert planned_evaluations(ds.Problem(params={"hfov": (30, 100)}, steps=[30, 100], dense_check=0.7)) == \
        2 * 2 + 20 + 2 + 101


def test_the_memory_estimate_is_variants_frames_vehicles_and_fields(tmp_path):
    # sc01 runs 20 s at 10 Hz (201 frames) with 5 vehicles and no background ones
    assert memory_estimate_bytes(ds.Problem(scenarios=["sc01"], variants=2)) == 2 * 201 * 5 * 8 * 20
    problem = ds.Problem(scenarios=["sc01", "sc02"], variants=3, float64=False, background_vehicles=10,
                         estimator=ds.metrics.EstimatorConfig(kind="mc", samples=6))
    assert memory_estimate_bytes(problem) == 2 * 3 * 201 * 15 * 4 * (6 + 20)
    assert memory_estimate_bytes(ds.Problem(scenarios=["sc01"], estimator="mean-field", float64=False)) == \
        8 * 201 * 5 * 4 * 20  # the Monte-Carlo draws only for "mc"
    csv = tmp_path / "t.csv"
    csv.write_text("")
    assert memory_estimate_bytes(ds.Problem(scenes=f"ngsim:{csv}")) == 0


def test_the_recorded_config_names_the_sensor_the_predictor_and_the_params():
    config = _config(ds.Problem(params={"hfov": (30, 90)}, variants=3))
    assert config["sensor"] == "radar" and config["params"] == {H: [30.0, 90.0]} and config["variants"] == 3
    assert config["predictor"] == "" and config["solve"]["max_evaluations"] == 20 and config["weather"] is None
    suite = ds.Problem(sensor=[make_sensor("radar"), "camera"], params={"camera.hfov": (30, 60)},
                       predictor=ToyPredictor(jnp.asarray(TOY_GAIN)))
    config = _config(suite)
    assert config["sensor"] == ["radar", "camera"] and config["predictor"] == "ToyPredictor"
    assert config["params"] == {"camera.hfov_deg": [30.0, 60.0]}
    assert set(config) == {f for f in ds.Problem.__dataclass_fields__}


def test_the_predictor_computes_in_the_precision_asked_for():
    toy = ToyPredictor(jnp.asarray(TOY_GAIN))
    assert _in_dtype(toy, "auto", jnp.float64) is toy and _in_dtype(toy, "float64", jnp.float64) is toy
    cast = _in_dtype(toy, "float32", jnp.float64)
    assert isinstance(cast, CastPredictor) and cast.inner is toy and cast.dtype == "float32"
    assert _in_dtype(toy, "float32", jnp.float32) is toy
    cs_lstm = init_predictor()
    cast = _in_dtype(cs_lstm, "auto", jnp.float64)  # the CS-LSTM in float32, its weights' precision
    assert isinstance(cast, CastPredictor) and cast.inner is cs_lstm and cast.dtype == "float32"
    assert _in_dtype(cs_lstm, "auto", jnp.float32) is cs_lstm
    recast = _in_dtype(CastPredictor(inner=cs_lstm, dtype="float64"), "auto", jnp.float64)
    assert recast.inner is cs_lstm and recast.dtype == "float32"  # never two casts deep


def _toy_objective(problem, predictor):
    scenes, scenario = toy_scenes(1)
    frames = prediction_frames(scenes.num_frames)[:3]
    return make_objective(scenes, scenario, frames, problem.make_sensor(), predictor, names=(H,), shard=False)


@pytest.fixture(scope="module")
def solved():
    problem = ds.Problem(params={H: (20.0, 100.0)}, steps=(20.0, 60.0, 100.0), dense_check=40.0, extra_curve_points=4,
                         solve=SolveConfig(max_evaluations=9), scenarios=["sc01"])
    E = _toy_objective(problem, ValidatedToyPredictor(jnp.asarray(TOY_GAIN)))
    lines, events = [], []
    result = ds.optimise(problem, E=E, progress=lines.append, on_evaluation=events.append)
    return problem, result, lines, events


def test_a_one_parameter_solve_is_wired_into_its_result(solved):
    problem, result, _, _ = solved
    s = result.solve
    assert result.r_star == {H: s.r_star} and type(result.r_star[H]) is float
    assert result.E_hard_star == s.E_hard_star and result.E_soft_star == s.E_soft_star
    assert result.params == {H: (20.0, 100.0)} and result.units == {H: "deg"} and result.sensor == "radar"
    assert [p.r for p in s.sweep] == [20.0, 60.0, 100.0] and result.scenarios == ("scenario0",)
    assert result.config == _config(problem) and result.reference["answer_on"] == "E_hard"
    assert result.curves is not None and list(result.curves.r) == sorted(result.curves.r)
    assert set(result.wall_s) == {"compile", "run", "programs_compiled", "programs_lowered"}
    assert result.near_optimal["intervals"] and result.flags == tuple(result.to_json()["flags"])


def test_the_dense_check_and_the_domain_note_end_the_notes(solved):
    _, result, lines, _ = solved
    assert result.dense_check["step"] == 40.0 and result.dense_check["evaluations"] == 3  # 20, 60, 100
    assert result.domain["validation_rmse_m"] == (0.01, 0.02, 0.03, 0.04, 0.05)
    assert result.domain["outside"] == ["scenario0"]
    assert result.notes[-2:] == ("dense check: " + result.dense_check["verdict"], domain_note(result.domain))
    assert lines[1] == "warning: " + domain_note(result.domain)  # before the solve starts


def test_progress_lines_and_events(solved):
    problem, result, lines, events = solved
    lines = [line for line in lines if not line.startswith("warning: ")]
    assert lines[0] == "radar: simulating 1 scenarios x 8 variants; ground-truth predictions"
    assert lines[1] == "radar: stepped sweep and continuous solve of hfov_deg over [20, 100] deg"
    assert lines[2] == f"radar: r* = {result.r_star[H]:.5g} deg, E_hard(r*) = {result.E_hard_star:.4f} m"
    assert lines[3] == "radar: dense reference grid every 40 deg" and len(lines) == 4
    planned = planned_evaluations(problem)
    assert all(e["planned"] == planned for e in events)
    assert [e["done"] for e in events] == list(range(1, len(events) + 1))
    solve, figures = result.programs_run["solve"], result.programs_run["figures"]
    assert sum(solve.values()) + sum(figures.values()) == len(events) and sum(figures.values()) > 0
    assert solve["soft"] >= result.solve.evaluations["gradient"]  # the solver's gradients are the evaluator's


def test_a_cost_weight_makes_one_parameter_a_box_solve(monkeypatch):
    from diffsense.study import _box_job as _suite_solve

    called = []
    monkeypatch.setattr(_suite_solve, "optimise_box", lambda problem, *a: called.append(problem) or "box")
    problem = ds.Problem(cost_weight=0.5)
    assert ds.optimise(problem) == "box" and called == [problem]


def test_an_unknown_odd_parameter_is_refused_before_any_work():
    with pytest.raises(ds.InputError, match="no sensitivity to 'snow'"):
        ds.optimise(ds.Problem(predictor=object()), sensitivity=("snow",))


def test_the_hard_estimator_searches_the_steps_it_is_given():
    problem = ds.Problem(params={H: (20.0, 100.0)}, steps=(20.0, 45.0, 100.0), estimator="hard",
                         solve=SolveConfig(max_evaluations=9), scenarios=["sc01"])
    result = ds.optimise(problem, E=_toy_objective(problem, ToyPredictor(jnp.asarray(TOY_GAIN))), figures=False)
    assert [p.r for p in result.solve.sweep] == [20.0, 45.0, 100.0]
    assert result.solve.evaluations["objective"] <= 9 and result.reference["answer_on"] == "E_hard"


def test_sensitivity_is_asked_for_at_the_answer_and_kept(solved, monkeypatch):
    from diffsense.study import _sensitivity

    problem, result, _, _ = solved
    asked = []
    monkeypatch.setattr(_sensitivity, "sensitivity",
                        lambda p, out, theta, E: asked.append((p, out.r_star, theta)) or {"rain_mm_h": {H: 0.5}})
    monkeypatch.setattr(ds._optimise, "_optimise_line", lambda *a: (result, "E"))
    lines = []
    theta = ("rain_mm_h", "fog_visibility_m")
    out = ds.optimise(problem, sensitivity=theta, progress=lines.append)
    assert asked == [(problem, result.r_star, theta)] and out.sensitivity == {"rain_mm_h": {H: 0.5}}
    assert out.r_star == result.r_star
    assert lines == ["radar: dr*/dtheta for rain_mm_h, fog_visibility_m (implicit function theorem)"]


@pytest.mark.parametrize("distributed, kwargs", [(True, {}), ({"process_id": 1, "num_processes": 2}, None)])
def test_a_distributed_run_is_joined_first(monkeypatch, distributed, kwargs):
    from diffsense.runtime import _distributed

    class Joined(Exception):
        pass

    def initialize(**given):
        raise Joined(given)

    monkeypatch.setattr(_distributed, "initialize", initialize)
    with pytest.raises(Joined) as joined:
        ds.optimise(ds.Problem(), distributed=distributed)
    assert joined.value.args[0] == (distributed if kwargs is None else kwargs)


def test_float64_switches_jax_to_64_bits_in_a_fresh_process():
    import os
    import subprocess
    import sys

    code = ("import jax; from diffsense.study._optimise import _precision; "
            "print(jax.config.jax_enable_x64, _precision(False).__name__, jax.config.jax_enable_x64, "
            "_precision(True).__name__, jax.config.jax_enable_x64)")
    env = {k: v for k, v in os.environ.items() if k != "JAX_ENABLE_X64"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True).stdout
    assert out.split() == ["False", "float32", "False", "float64", "True"]


def test_under_a_probabilistic_law_the_near_optimal_set_is_judged_on_e_ref():
    from tests.test_reference import radar_objective

    # radar_objective: the Swerling I radar on one toy scene, three instants

    problem = ds.Problem(params={H: (20.0, 100.0)}, steps=(20.0, 60.0, 100.0),
                         sensor_config="configs/sensors/laws/radar_swerling1.toml",
                         estimator=ds.metrics.EstimatorConfig(reference_draws=4),
                         solve=SolveConfig(max_evaluations=9), scenarios=["sc01"])
    result = ds.optimise(problem, E=radar_objective(kind="auto", draws=4), figures=False)
    assert result.reference["answer_on"] == "E_ref"
    # the tolerance is 0.5 % of the best E_ref evaluated, which is r*'s (the answer is chosen on it)
    assert result.near_optimal["tolerance_m"] == pytest.approx(0.005 * result.reference["E_ref_star"], rel=1e-12)


def test_under_straight_through_the_sweep_reads_e_soft_off_e_ref_and_every_value_is_a_candidate():
    from diffsense.solve import Evaluator, solve
    from tests.test_reference import radar_objective

    config = SolveConfig(max_evaluations=9)
    problem = ds.Problem(params={H: (20.0, 100.0)}, steps=(20.0, 60.0, 100.0),
                         sensor_config="configs/sensors/laws/radar_swerling1.toml",
                         estimator=ds.metrics.EstimatorConfig(reference_draws=4), solve=config, scenarios=["sc01"])
    E, events = radar_objective(kind="auto", draws=4), []
    assert E.estimator_kind == "straight-through"
    result = ds.optimise(problem, E=E, figures=False, on_evaluation=events.append)
    # the sweep: one E_ref program per step, no value-and-gradient; E_soft is that E_ref
    assert [e["kind"] for e in events[:3]] == ["reference"] * 3
    assert [p.E_soft for p in result.solve.sweep] == [p.E_hard for p in result.solve.sweep]
    assert [p.E_hard for p in result.solve.sweep] == [e["E_m"] for e in events[:3]]
    # every program is counted, E_ref's too, and the plan knows the sweep runs one per step
    assert [e["done"] for e in events] == list(range(1, len(events) + 1))
    assert {e["planned"] for e in events} == {planned_evaluations(problem, sweep_soft=False)}
    # the solve with the sweep's value-and-gradient programs run (as for any other estimator):
    # the same answer when its gradient evaluations' values are answer candidates too, a worse
    # one here when they are not
    solved, soft_programs = {}, {}
    for seen in (True, False):
        ev = Evaluator(E)
        solved[seen] = solve(ev.solver_fns()[0], ev.e_reference, (20.0, 100.0), steps=(20.0, 60.0, 100.0),
                             config=config, value_and_grad=ev.host_value_and_grad, answer_name="E_ref",
                             soft_value_is_answer=seen)
        soft_programs[seen] = ev.counts["soft"]
    assert (result.solve.r_star, result.solve.E_hard_star) == (solved[True].r_star, solved[True].E_hard_star)
    assert result.solve.E_hard_star < solved[False].E_hard_star
    assert [p.E_soft for p in solved[True].sweep] == [p.E_hard for p in solved[True].sweep]
    assert result.programs_run["solve"]["soft"] == soft_programs[True]  # the same programs, the sweep's none


def test_with_figures_the_plan_counts_the_sweeps_value_and_gradients_which_the_figures_draw():
    from tests.test_reference import radar_objective

    problem = ds.Problem(params={H: (20.0, 100.0)}, steps=(20.0, 60.0, 100.0), extra_curve_points=0,
                         sensor_config="configs/sensors/laws/radar_swerling1.toml",
                         estimator=ds.metrics.EstimatorConfig(reference_draws=4), solve=SolveConfig(max_evaluations=9),
                         scenarios=["sc01"])
    events = []
    result = ds.optimise(problem, E=radar_objective(kind="auto", draws=4), on_evaluation=events.append)
    assert {e["planned"] for e in events} == {planned_evaluations(problem, sweep_soft=True)}
    assert result.programs_run["figures"]["soft"] >= 3  # the sweep's steps, drawn with their slope


@pytest.mark.parametrize(("threshold_law", "kind", "expected"), [
    (False, "auto", True), (False, "straight-through", True), (False, "relaxed-reference", False),
    (False, "mean-field", False), (True, "straight-through", False), (True, "auto", False)])
def test_only_straight_through_under_a_probabilistic_law_has_e_ref_for_its_value(threshold_law, kind, expected):
    from diffsense.study._optimise import _soft_value_is_e_ref
    from diffsense.sensors import Radar
    from tests.test_reference import SWERLING, radar_objective

    # under the threshold law straight-through is mean-field: its value is not E_hard
    E = radar_objective(Radar.from_toml() if threshold_law else SWERLING, kind=kind)
    assert _soft_value_is_e_ref(E) is expected


def test_under_straight_through_the_default_steps_are_swept_and_the_notes_name_e_ref():
    from diffsense.solve import default_steps
    from tests.test_reference import radar_objective

    problem = ds.Problem(params={H: (20.0, 100.0)}, sensor_config="configs/sensors/laws/radar_swerling1.toml",
                         estimator=ds.metrics.EstimatorConfig(reference_draws=4), solve=SolveConfig(max_evaluations=9),
                         scenarios=["sc01"])
    result = ds.optimise(problem, E=radar_objective(kind="auto", draws=4), figures=False)
    assert [p.r for p in result.solve.sweep] == list(default_steps(20.0, 100.0))  # 20, 36, ..., 100
    assert result.notes[-1].startswith("a gradient evaluation saw a lower E_ref than the levels' answer")
