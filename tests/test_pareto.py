"""The E-versus-cost front (`ds.pareto`): on a tiny fused radar+camera problem (the toy predictor,
1 scene, 3 instants) the designs marked as the front are non-dominated and the others dominated,
each design's J is its E plus lambda times its cost, the progress events carry the cost, and bad
cost weights are refused before any work. pareto.json's keys: tests/test_box_job.py."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import diffsense as ds
from diffsense.metrics import make_objective
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
    E = make_objective(scenes, scenario, frames, problem.sensing.built, ToyPredictor(jax.numpy.asarray(TOY_GAIN)),
                       names=tuple(PARAMS), key=jax.random.key(2, impl="rbg"),
                       estimator=ds.metrics.EstimatorConfig(reference_draws=4))  # the physical laws, 4 draws
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


def test_bad_cost_weights_are_refused_before_any_work():
    with pytest.raises(ds.InputError, match="cost weight 0.01 is given twice"):
        ds.pareto(ds.Problem(sensor=["radar", "camera"], params=PARAMS, predictor=object()), (0.01, 0.02, 0.01))
