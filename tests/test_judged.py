"""An answer judged on data it was not chosen on: result.json's "judged" is E_ref at r* over the
scene variants, noise and detection draws of another seed, and equals that evaluation made
independently."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import diffsense as ds

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")


def _problem(**changes) -> ds.Problem:
    fields = dict(sensor="radar", params={"hfov_deg": (30.0, 120.0)}, scenarios=["sc01"], variants=2, seed=3,
                  steps=(30.0, 75.0, 120.0),
                  solve=ds.solve.SolveConfig(tau_schedule=(1.0,), max_evaluations=4, hard_polish=0),
                  estimator=ds.metrics.EstimatorConfig(reference_draws=4), prediction_stride_frames=8)
    return ds.Problem(**fields | changes)


@pytest.fixture(scope="module")
def solved():
    problem = _problem()
    E = ds.objective(problem)
    return problem, E, ds.optimise(problem, E=E, figures=False, judge=True)


def _e_ref(problem: ds.Problem, r_star: dict[str, float]):
    E = ds.objective(problem)
    x = np.asarray([r_star[n] for n in E.names])
    return jax.jit(lambda E, x: E.reference(E.point(x)))(E, x)


def test_the_judged_value_is_e_ref_at_r_star_on_the_fresh_seed(solved):
    problem, _, result = solved
    judged = result.judged
    assert set(judged) == {"E_ref", "E_ref_se", "E_ci", "seed", "variants"}
    assert judged["seed"] != problem.seed and judged["variants"] == problem.traffic.variants
    fresh = _e_ref(problem.replace(seed=judged["seed"]), result.r_star)
    assert judged["E_ref"] == pytest.approx(float(fresh.e), rel=1e-12)
    assert judged["E_ref_se"] == pytest.approx(float(fresh.e_se), rel=1e-9)
    assert result.to_json()["judged"] == judged


def test_the_judged_value_is_not_the_optimised_one(solved):
    # other variants and other draws: the value the answer was chosen on is not the judged one
    problem, _, result = solved
    assert result.judged["E_ref"] != pytest.approx(result.reference["E_ref_star"], rel=1e-9)
    own = _e_ref(problem, result.r_star)
    assert result.reference["E_ref_star"] == pytest.approx(float(own.e), rel=1e-12)


def test_a_run_given_its_own_objective_is_not_judged_unless_asked(solved):
    problem, E, result = solved
    again = ds.optimise(problem, E=E, figures=False)  # the same objective: compiled once
    assert again.judged is None and again.r_star == result.r_star
