"""The design solve's two additions to the box solve, on problems worked by hand: a screened start
(a large space-filling sample ranked on a cheap value, only its best evaluated on the answer's
objective) and a descent whose iterates become answers as it goes (`check_every`); and the
batched reference they rest on (`Evaluator.reference_batch`: many r in one program, the first
draws of E_ref's own) and the box job's use of them under a probabilistic law."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffsense as ds
from diffsense.runtime import InputError
from diffsense.solve import BoxConfig, BoxFunctions, Evaluator, box_solve
from diffsense.metrics import EstimatorConfig, make_objective
from diffsense.tracks import prediction_frames
from tests._toy_pipeline import SWERLING as SWERLING_RADAR
from tests._toy_pipeline import TOY_GAIN, ToyPredictor, toy_scenes
from tests.test_box_job import SWERLING, TINY, _problem, _toy_objective

NAMES = ("a_m", "b_m")
BOUNDS = {"a_m": (0.0, 10.0), "b_m": (0.0, 10.0)}


@pytest.fixture(autouse=True)
def _x64():
    jax.config.update("jax_enable_x64", True)


def well(x, tau=1.0):
    """E^2 [m^2]: 50 m everywhere but a narrow well at (9, 9), 1 m deep in E^2 terms; the same at
    every temperature (no continuation widens it)."""
    return 2500.0 - 2499.0 * jnp.exp(-jnp.sum((x - 9.0) ** 2) / (2.0 * 0.6**2))


def plateau(screen=None):
    return BoxFunctions(NAMES, *_host(well), e_screen=screen)


def _host(e2):
    vg = jax.jit(jax.value_and_grad(e2))

    def soft(x, tau):
        v, g = vg(jnp.asarray(x), jnp.asarray(tau))
        return float(v), np.asarray(g)

    return soft, lambda x: float(np.sqrt(e2(jnp.asarray(x))))


def _exact_screen(fns_e_hard):
    return lambda xs: np.array([fns_e_hard(x) for x in xs])


def test_only_the_screens_best_are_evaluated_on_the_answers_objective():
    e_hard = _host(well)[1]
    fns = plateau(_exact_screen(e_hard))
    result = box_solve(fns, BOUNDS, BoxConfig(starts=3, max_soft=0, seed=4))
    screened = [(e.value, e.x) for e in result.history if e.kind == "screen"]
    hard = [e.x for e in result.history if e.kind == "hard"]
    assert result.counts["screen"] == len(screened) == 8 * 2 + 8  # the default screen: 8 d + 8
    best_three = [x for _, x in sorted(screened)[:3]]
    assert hard == best_three  # in the screen's order, and nothing else before a descent
    assert result.J_star == pytest.approx(min(v for v, _ in screened), rel=1e-12)


def test_a_screen_finds_the_well_that_the_hard_sample_misses():
    # The well is put at the screened point farthest from the 2 d + 2 = 6 points of the hard
    # sample: they all lie on the plateau (the gradient there ~0), the screen's best in the well.
    flat = lambda xs: np.full(len(xs), 50.0)  # noqa: E731
    probe = box_solve(plateau(flat), BOUNDS, BoxConfig(starts=1, max_soft=0, screen_points=40))
    sample = box_solve(plateau(), BOUNDS, BoxConfig(starts=6, max_soft=0))
    screened = np.array([e.x for e in probe.history if e.kind == "screen"])
    hard = np.array([e.x for e in sample.history if e.kind == "hard"])
    distance = np.min(np.linalg.norm(screened[:, None] - hard[None], axis=-1), axis=1)
    centre = screened[np.argmax(distance)]
    assert distance.max() > 2.5  # 4 widths of the well from every point of the hard sample

    def e2(x, tau=1.0):
        return well(x - centre + 9.0)

    soft, e_hard = _host(e2)
    config = BoxConfig(starts=1, max_soft=30, screen_points=40)
    unscreened = box_solve(BoxFunctions(NAMES, soft, e_hard), BOUNDS, config)
    found = box_solve(BoxFunctions(NAMES, soft, e_hard, e_screen=_exact_screen(e_hard)), BOUNDS, config)
    assert unscreened.J_star > 49.0
    assert found.J_star < 1.01 and np.allclose(list(found.x_star.values()), centre, atol=0.05)


def test_screen_points_minus_one_is_the_hard_sample():
    e_hard = _host(well)[1]
    a = box_solve(plateau(_exact_screen(e_hard)), BOUNDS, BoxConfig(starts=1, max_soft=0, screen_points=-1))
    b = box_solve(plateau(), BOUNDS, BoxConfig(starts=1, max_soft=0))
    assert "screen" not in a.counts and a.history == b.history


def test_screened_points_are_memoised_across_solves():
    calls = []

    def screen(xs):
        calls.append(len(xs))
        return np.full(len(xs), 50.0)

    fns = plateau(screen)
    for _ in range(2):
        box_solve(fns, BOUNDS, BoxConfig(starts=1, max_soft=0, screen_points=10))
    assert fns.counts["screen"] == 10 and sum(calls) == 10


def test_a_descents_iterate_is_an_answer_where_the_levels_end_is_worse():
    # The soft bowl's minimum is at 5; the hard objective is the bowl plus a 10 m bump within
    # 0.2 of 5: the level ends in the bump, while the iterates on the way do not.
    def soft(x, tau):
        return float(np.sum((x - 5.0) ** 2) + 1.0), 2.0 * (np.asarray(x) - 5.0)

    def hard(x):
        x = np.asarray(x)
        return float(np.sqrt(np.sum((x - 5.0) ** 2) + 1.0) + (10.0 if np.max(np.abs(x - 5.0)) < 0.2 else 0.0))

    config = BoxConfig(samples=1, starts=1, tau_schedule=(1.0,), max_steps=30, check_every=1, seed=3)
    checked = box_solve(BoxFunctions(NAMES, soft, hard), BOUNDS, config)
    ends = box_solve(BoxFunctions(NAMES, soft, hard), BOUNDS, dataclasses.replace(config, check_every=0))
    assert checked.source.endswith("step") and checked.J_star < 10.0
    assert ends.J_star > checked.J_star and not ends.source.endswith("step")


@pytest.mark.parametrize("kwargs, culprit", [
    (dict(screen_points=-2), "screen_points"), (dict(screen_draws=1), "screen_draws"),
    (dict(check_every=-1), "check_every"),
])
def test_a_bad_screen_or_check_setting_is_one_input_error(kwargs, culprit):
    with pytest.raises(InputError, match=culprit):
        BoxConfig(**kwargs)


def test_the_batched_reference_is_each_points_own_on_the_first_draws():
    scenes, scenario = toy_scenes(1)
    E = make_objective(scenes, scenario, prediction_frames(scenes.num_frames)[:3], SWERLING_RADAR,
                       ToyPredictor(jnp.asarray(TOY_GAIN)), names=("hfov_deg", "range_m"),
                       estimator=EstimatorConfig(kind="relaxed-reference", reference_draws=6))
    ev = Evaluator(E)
    xs = np.array([[30.0, 80.0], [60.0, 120.0], [90.0, 40.0], [120.0, 150.0], [45.0, 60.0]])
    batched = ev.reference_batch(xs, batch=2)  # three programs, the last one padded
    single = [ev.e_reference(x) for x in xs]
    np.testing.assert_allclose(batched, single, rtol=1e-12)
    first = ev.reference_batch(xs, draws=3, batch=4)
    want = [float(E.reference(E.point(jnp.asarray(x)), jnp.arange(3)).e) for x in xs]
    np.testing.assert_allclose(first, want, rtol=1e-12)


def test_under_a_random_law_the_box_job_screens_and_reports_it():
    problem = _problem(sensor_config=SWERLING, box=dataclasses.replace(TINY, screen_points=6))
    result = ds.optimise(problem, E=_toy_objective(problem))
    assert result.evaluations["screened"] == 6 + 1  # the screen and the sensors' default point
    threshold = _problem(box=TINY)
    assert "screened" not in ds.optimise(threshold, E=_toy_objective(threshold)).evaluations
