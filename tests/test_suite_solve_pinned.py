"""The many-parameter main job's bookkeeping, pinned: the cost weights a front accepts, the
front's order and pareto.json, the evaluations a progress display plans for, which objective an
answer is judged on, and the Result a box solve returns (on the toy pipeline: one tiny scene).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from types import SimpleNamespace

import jax
import pytest

import diffsense as ds
from diffsense.study._domain import domain_note
from diffsense.study._box_job import (
    ParetoFront,
    _functions,
    _on_hard,
    _planned,
    check_lambdas,
    pareto,
)
from diffsense.runtime._errors import InputError
from diffsense.metrics import make_objective
from diffsense.solve import BoxConfig
from diffsense.tracks import prediction_frames
from tests._toy_pipeline import (
    TOY_GAIN,
    ToyPredictor,
    ValidatedToyPredictor,
    toy_scenes,
)
from tests.test_result_pinned import _box

PARAMS = {"radar.range_m": (30.0, 200.0), "camera.width_px": (640.0, 3840.0)}
SWERLING = {"radar": "configs/sensors/laws/radar_swerling1.toml"}


def _problem(**changes) -> ds.Problem:
    return ds.Problem(**{"sensor": ["radar", "camera"], "params": PARAMS} | changes)


def test_cost_weights_are_sorted_floats():
    assert check_lambdas([0.05, 0, 0.01]) == (0.0, 0.01, 0.05)
    assert all(type(v) is float for v in check_lambdas([0, 1]))


@pytest.mark.parametrize("lambdas", [[], [0.01], [0.0, -0.01], [0.0, math.nan], [0.0, math.inf]])
def test_too_few_or_bad_cost_weights_are_refused_with_the_list(lambdas):
    with pytest.raises(InputError) as caught:
        check_lambdas(lambdas)
    assert str(caught.value) == f"a Pareto sweep needs at least two cost weights >= 0, got {list(lambdas)}"


def test_a_repeated_cost_weight_is_named_the_smallest_first():
    with pytest.raises(InputError, match=r"^cost weight 0\.02 is given twice$"):
        check_lambdas([0.05, 0.02, 0.05, 0.02, 0.1])


def test_the_planned_evaluations_are_the_budget_per_solve_and_the_sample():
    assert _planned(_problem(box=BoxConfig(max_soft=12))) == 12 + 2 * 2 + 2
    assert _planned(_problem(box=BoxConfig(max_soft=12)), solves=3) == 36 + 6
    assert _planned(_problem(box=BoxConfig(max_soft=7, samples=5)), solves=2) == 14 + 5


def test_answers_are_judged_on_e_hard_under_the_threshold_law_or_the_hard_estimator():
    threshold = _problem()
    random = _problem(sensor_config=SWERLING)
    assert _on_hard(threshold, SimpleNamespace(sensor=threshold.make_sensor())) is True
    assert _on_hard(random, SimpleNamespace(sensor=random.make_sensor())) is False
    hard = dataclasses.replace(random, estimator="hard")
    assert _on_hard(hard, SimpleNamespace(sensor=hard.make_sensor())) is True


def _front(judged_on="E_hard") -> ParetoFront:
    designs = (_box(cost=3.0, E_hard=4.0), _box(cost=1.0, E_hard=6.0), _box(cost=2.0, E_hard=7.0),
               _box(cost=0.5, E_hard=9.0))
    return ParetoFront(sensor="radar+camera", units={"hfov_deg": "deg"}, currency="EUR", lambdas=(0.0, 0.01, 0.02, 0.05),
                       designs=designs, on_front=(True, True, False, True), cloud=((1.0, 6.0), (3.0, 4.0)),
                       counts={"soft": 20, "hard": 9}, wall_s=12.5, judged_on=judged_on)


def test_the_front_is_its_non_dominated_designs_cheapest_first():
    assert _front().front() == [3, 1, 0]


@pytest.mark.parametrize("judged_on", ["E_hard", "E_ref"])
def test_pareto_json(judged_on):
    front = _front(judged_on)
    out = front.to_dict()
    key = f"{judged_on}_m"
    assert list(out) == ["sensor", "judged_on", "currency", "units", "lambdas", "designs", "front", "evaluations",
                         "wall_s", "cloud"]
    assert (out["sensor"], out["judged_on"], out["currency"], out["units"]) == ("radar+camera", judged_on, "EUR",
                                                                                {"hfov_deg": "deg"})
    assert out["lambdas"] == [0.0, 0.01, 0.02, 0.05] and out["front"] == [3, 1, 0]
    assert out["evaluations"] == {"soft": 20, "hard": 9} and out["wall_s"] == 12.5
    assert out["cloud"] == {"cost": [1.0, 3.0], key: [6.0, 4.0]}
    d = front.designs[2]
    assert out["designs"][2] == {"lambda": 0.02, "r_star": d.x_star, key: 7.0, "E_soft_m": d.E_soft, "cost": 2.0,
                                 "J": d.J_star, "on_front": False, "on_bound": d.on_bound, "gradient": d.gradient,
                                 "source": d.source, "evaluations": d.counts}


def _toy_objective(problem, predictor=None):
    scenes, scenario = toy_scenes(1)
    frames = prediction_frames(scenes.num_frames)[:3]
    predictor = ToyPredictor(jax.numpy.asarray(TOY_GAIN)) if predictor is None else predictor
    return make_objective(scenes, scenario, frames, problem.make_sensor(), predictor,
                          names=tuple(PARAMS), key=jax.random.key(2, impl="rbg"))


def test_the_start_is_the_sensors_defaults_clipped_into_the_box_and_events_carry_the_cost():
    problem = _problem(params={"radar.range_m": (30.0, 60.0), "camera.width_px": (640.0, 3840.0)})
    E = _toy_objective(_problem())
    events = []
    _, fns, start = _functions(problem, E, events.append, planned=1)
    defaults = E.sensor.defaults()
    assert defaults["radar.range_m"] > 60.0 and start == [60.0, defaults["camera.width_px"]]
    fns.e_hard(start)
    (event,) = events
    assert event["kind"] == "hard" and event["E_m"] == fns.e_hard(start) and event["cost"] == fns.cost(start)[0]
    assert event["done"] == 1 and event["planned"] == 1 and event["tau"] is None
    fns.e_hard([30.0, 640.0])
    assert events[-1]["done"] == 2 and events[-1]["planned"] == 2  # never fewer planned than done


@pytest.fixture(scope="module")
def boxed():
    problem = _problem(box=BoxConfig(samples=4, starts=1, tau_schedule=(2.0, 1.0), max_steps=3, max_soft=6,
                                      bound_tol=0.02),
                       cost_weight=1.0, scenarios=["sc01"])
    E = _toy_objective(problem, ValidatedToyPredictor(jax.numpy.asarray(TOY_GAIN)))
    lines, events = [], []
    return problem, ds.optimise(problem, E=E, progress=lines.append, on_evaluation=events.append), lines, events


def test_a_box_solve_returns_its_answer_in_a_result(boxed):
    _, result, lines, events = boxed
    box = result.box
    assert result.solve is None and result.sensor == "radar+camera" and result.r_star == box.x_star
    assert result.params == PARAMS and result.units == {"radar.range_m": "m", "camera.width_px": "px"}
    assert result.E_soft_star == box.E_soft and result.E_hard_star == box.E_hard  # the threshold law: E_hard
    assert result.reference["answer_on"] == "E_hard" and result.scenarios == ("scenario0",)
    assert box.cost_weight == 1.0 and result.config["cost_weight"] == 1.0
    assert result.programs_run["figures"] == {"soft": 0, "hard": 0}
    assert sum(result.programs_run["solve"].values()) >= box.counts["soft"] + box.counts["hard"]
    assert set(result.wall_s) == {"compile", "run", "programs_compiled", "programs_lowered"}
    assert result.breakdown["by_scenario"]["scenario0"]["E_hard"] == pytest.approx(result.E_hard_star, rel=1e-9)
    assert lines == ["radar+camera: simulating 1 scenarios x 8 variants",
                     "radar+camera: box solve of radar.range_m, camera.width_px"]
    assert events[0]["planned"] == 6 + 4 and events[0]["done"] == 1  # the soft budget and the sample


def test_a_parameter_on_its_bound_is_noted(boxed):
    result = boxed[1]  # a cost weight of 1 m per EUR: the cheapest design, both parameters on their lower bounds
    assert result.box.on_bound == {"radar.range_m": "lower", "camera.width_px": "lower"}
    assert result.r_star == {"radar.range_m": 30.0, "camera.width_px": 640.0}
    assert result.domain["validation_rmse_m"] == (0.01, 0.02, 0.03, 0.04, 0.05)
    assert result.domain["outside"] == ["scenario0"]
    assert result.box_notes == ("radar.range_m is on its lower bound", "camera.width_px is on its lower bound",
                                domain_note(result.domain))
    assert result.notes == result.box_notes and result.on_bound is True


def test_a_pareto_sweep_builds_its_objective_seeds_its_solves_and_says_each_lambda(monkeypatch):
    from diffsense import _optimise, _suite_solve

    problem = _problem(box=BoxConfig(samples=4, starts=1, tau_schedule=(1.0,), max_steps=2, max_soft=3), seed=5)
    built, configs = [], []
    E = _toy_objective(problem)
    monkeypatch.setattr(_optimise, "objective", lambda p, predictor=None: built.append((p, predictor)) or E)
    sweep = _suite_solve.pareto_sweep
    monkeypatch.setattr(_suite_solve, "pareto_sweep",
                        lambda fns, params, lambdas, config, **kw: configs.append(config) or sweep(fns, params, lambdas,
                                                                                                   config, **kw))
    lines = []
    front = pareto(problem, [0.01, 0.0], predictor="toy", progress=lines.append)
    assert built == [(problem, "toy")] and configs[0].seed == 5 and configs[0].max_soft == 3
    assert front.lambdas == (0.0, 0.01) and isinstance(front.wall_s, float) and front.wall_s > 0
    assert lines[0] == "radar+camera: simulating 6 scenarios x 8 variants"
    for k, (lam, design) in enumerate(zip(front.lambdas, front.designs)):
        assert lines[k + 1] == (f"radar+camera: lambda {lam:g} ({k + 1}/2): E_hard {design.E_hard:.4f} m, "
                                f"cost {design.cost:.2f}, {design.counts['soft']} value-and-gradient + "
                                f"{design.counts['hard']} hard")
    assert len(lines) == 3


def test_under_a_random_law_answers_are_judged_on_e_ref():
    problem = _problem(sensor_config=SWERLING)
    E = _toy_objective(problem)
    ev, fns, _ = _functions(problem, E, None, planned=1)
    x = [60.0, 1920.0]
    assert fns.e_hard(x) == ev.e_reference(x) and fns.e_hard(x) != ev.e_hard(x)


def _costs_file(tmp_path) -> str:
    """configs/costs.toml in dollars, the radar's base 45 higher."""
    text = (Path(__file__).resolve().parents[1] / "configs" / "costs.toml").read_text()
    assert text.count('currency = "EUR"') == 1 and text.count("base = 45.0") == 1
    path = tmp_path / "costs.toml"
    path.write_text(text.replace('currency = "EUR"', 'currency = "USD"').replace("base = 45.0", "base = 90.0"))
    return str(path)


def test_the_box_functions_price_a_design_with_the_problems_cost_model(tmp_path):
    E = _toy_objective(_problem())
    x = [60.0, 1920.0]
    default = _functions(_problem(), E, None, planned=1)[1].cost(x)[0]
    priced = _functions(_problem(costs=_costs_file(tmp_path)), E, None, planned=1)[1].cost(x)[0]
    assert priced == pytest.approx(default + 45.0, rel=1e-12)


def test_a_box_solve_is_seeded_by_the_problem(monkeypatch):
    from diffsense.study import _box_job as _suite_solve

    configs = []
    solve = _suite_solve.box_solve
    monkeypatch.setattr(_suite_solve, "box_solve",
                        lambda fns, params, config, **kw: configs.append(config) or solve(fns, params, config, **kw))
    problem = _problem(box=BoxConfig(samples=4, starts=1, tau_schedule=(1.0,), max_steps=2, max_soft=3), seed=7)
    ds.optimise(problem, E=_toy_objective(problem))
    assert [c.seed for c in configs] == [7]


def test_a_front_is_priced_in_the_cost_models_currency(monkeypatch, tmp_path):
    from diffsense.study import _optimise

    problem = _problem(box=BoxConfig(samples=4, starts=1, tau_schedule=(1.0,), max_steps=2, max_soft=3),
                       costs=_costs_file(tmp_path))
    E = _toy_objective(problem)
    monkeypatch.setattr(_optimise, "objective", lambda p, predictor=None: E)
    front = pareto(problem, [0.0, 0.01], predictor="toy")
    assert front.currency == "USD" and front.to_dict()["currency"] == "USD"
