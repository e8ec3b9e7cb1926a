"""The E-versus-cost front (`ds.pareto`, --pareto): on a tiny fused radar+camera problem (the toy
predictor, 1 scene, 3 instants) the designs marked as the front are non-dominated and the others
dominated, the progress events carry
the cost, pareto.json and pareto.png are written as one output set with every design labelled, and
bad cost weights are refused in one line."""

from __future__ import annotations

import dataclasses
import json

import jax
import numpy as np
import pytest

import diffsense as ds
from diffsense.runtime._io import output_set
from diffsense.metrics import EstimatorConfig, make_objective
from diffsense.report import PARETO_FILES, pareto_table, plot_pareto, write_pareto
from diffsense.solve import BoxConfig
from diffsense.tracks import prediction_frames
from tests._toy_pipeline import TOY_GAIN, ToyPredictor, toy_scenes

PARAMS = {"radar.range_m": (30.0, 200.0), "camera.width_px": (640.0, 3840.0)}
LAMBDAS = (0.0, 0.01, 0.05)


@pytest.fixture(scope="module")
def swept():
    problem = ds.Problem(sensor=["radar", "camera"], params=PARAMS,
                         box=BoxConfig(samples=4, starts=1, tau_schedule=(2.0, 1.0), max_steps=3, max_soft=12))
    scenes, scenario = toy_scenes(1)
    frames = prediction_frames(scenes.num_frames)[:3]
    E = make_objective(scenes, scenario, frames, problem.make_sensor(), ToyPredictor(jax.numpy.asarray(TOY_GAIN)),
                       names=tuple(PARAMS), key=jax.random.key(2, impl="rbg"))
    events, lines = [], []
    front = ds.pareto(problem, LAMBDAS, E=E, progress=lines.append, on_evaluation=events.append)
    return front, events, lines


def test_the_front_is_non_dominated_and_the_rest_dominated(swept):
    front, _, _ = swept
    assert front.lambdas == LAMBDAS and len(front.designs) == 3
    points = [(d.E_hard, d.cost) for d in front.designs]
    for i, (e, c) in enumerate(points):
        beaten = any(e2 <= e and c2 <= c and (e2, c2) != (e, c) for e2, c2 in points)
        assert front.on_front[i] == (not beaten)
    assert front.front() and all(front.on_front[i] for i in front.front())
    assert [front.designs[i].cost for i in front.front()] == sorted(front.designs[i].cost for i in front.front())
    for d, lam in zip(front.designs, LAMBDAS):
        assert d.cost_weight == lam and d.J_star == pytest.approx(d.E_hard + lam * d.cost)
        assert all(lo <= d.x_star[n] <= hi for n, (lo, hi) in PARAMS.items())


def test_progress_carries_e_and_cost_and_each_lambda_is_announced(swept):
    front, events, lines = swept
    assert len(events) == sum(front.counts.values())
    assert [e["done"] for e in events] == list(range(1, len(events) + 1))
    assert all(np.isfinite(e["E_m"]) and e["cost"] > 0 for e in events)
    assert sum(f"lambda {lam:g} (" in line for line in lines for lam in LAMBDAS) == 3


def test_pareto_json_and_png_are_written_as_one_set(swept, tmp_path):
    front, _, _ = swept
    out = tmp_path / "run"
    with output_set(out) as staging:
        content = write_pareto(front, staging)
    assert sorted(p.name for p in out.iterdir()) == sorted([*PARETO_FILES, "manifest.json"])  # the set's list
    saved = json.loads((out / "pareto.json").read_text())
    assert saved["front"] == front.front() and [d["lambda"] for d in saved["designs"]] == list(LAMBDAS)
    assert [d["on_front"] for d in saved["designs"]] == list(front.on_front)
    assert len(saved["cloud"]["cost"]) == front.counts["hard"]
    assert (out / "pareto.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    labels = plot_pareto(tmp_path / "again.png", content, "t")
    assert labels == [f"lambda = {lam:g}" for lam in LAMBDAS]
    table = pareto_table(content)
    assert "radar.range_m [m]" in table and len(table.splitlines()) == 2 + 1 + len(LAMBDAS)


@pytest.mark.parametrize("lambdas, match", [
    ((0.01,), "at least two cost weights"),
    ((0.0, -0.01), "at least two cost weights >= 0"),
    ((0.0, float("nan")), "at least two cost weights"),
    ((0.01, 0.02, 0.01), "cost weight 0.01 is given twice"),
])
def test_bad_cost_weights_are_refused(lambdas, match):
    problem = ds.Problem(sensor=["radar", "camera"], params=PARAMS)
    with pytest.raises(ds.InputError, match=match):
        ds.pareto(problem, lambdas)


def test_the_json_names_the_objective_its_values_are(swept, tmp_path):
    front, _, _ = swept  # the shipped threshold laws: the hard objective
    assert front.judged_on == "E_hard" and "E_hard_m" in front.to_dict()["designs"][0]
    # under a probabilistic law the same numbers are E_ref, and every reader says so
    as_ref = dataclasses.replace(front, judged_on="E_ref")
    content = as_ref.to_dict()
    assert content["judged_on"] == "E_ref" and "E_hard_m" not in json.dumps(content)
    assert [d["E_ref_m"] for d in content["designs"]] == [d.E_hard for d in front.designs]
    assert content["cloud"]["E_ref_m"] == [e for _, e in front.cloud]
    assert pareto_table(content).splitlines()[1].split()[:3] == ["lambda", "E_ref", "[m]"]
    assert len(plot_pareto(tmp_path / "ref.png", content, "t")) == len(LAMBDAS)


def test_a_sweep_under_random_laws_is_judged_on_the_reference():
    problem = ds.Problem.from_suite("configs/suites/radar_camera_laws_d2.toml",
                                    estimator=EstimatorConfig(reference_draws=2),
                                    box=BoxConfig(samples=3, starts=1, tau_schedule=(1.0,), max_steps=1, max_soft=2))
    scenes, scenario = toy_scenes(1)
    frames = prediction_frames(scenes.num_frames)[:2]
    E = make_objective(scenes, scenario, frames, problem.make_sensor(), ToyPredictor(jax.numpy.asarray(TOY_GAIN)),
                       names=tuple(problem.params), key=jax.random.key(2, impl="rbg"), estimator=problem.estimator)
    front = ds.pareto(problem, (0.0, 0.05), E=E)
    assert front.judged_on == "E_ref" and "E_ref_m" in front.to_dict()["cloud"]
