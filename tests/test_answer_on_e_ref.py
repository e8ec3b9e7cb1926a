"""One optimum, one answer, under a probabilistic detection law: the one-parameter job answers on
E_ref and `ds.sensitivity` is how that answer moves.

- The sensitivity of an answer chosen on E_ref is the slope of the answers the job itself gives
  at theta moved both ways (one-sided from rain 0): recomputed here with `ds.optimise` on the
  moved objective.
- Slow: on small real problems the answer lands within 0.1 % of the 1-deg dense grid's best of
  E_ref within 20 programs, and dr*/d(traffic speed) is within 10 % of answers re-solved at
  +-10 km/h (twice the sensitivity's own step).
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
import pytest

import diffsense as ds
from diffsense.metrics import EstimatorConfig
from diffsense.solve import Evaluator, SolveConfig, dense_grid_search
from diffsense.study import odd_shift
from tests._toy_pipeline import H, radar_objective

SWERLING1 = "configs/sensors/laws/radar_swerling1.toml"


def _toy_problem(**changes):
    return ds.Problem(**{"params": {H: (20.0, 100.0)}, "steps": (20.0, 60.0, 100.0), "sensor_config": SWERLING1,
                         "estimator": EstimatorConfig(reference_draws=4), "solve": SolveConfig(max_evaluations=9),
                         "scenarios": ["sc01"]} | changes)


def test_the_sensitivity_of_an_e_ref_answer_is_the_slope_of_the_jobs_own_answers():
    jax.config.update("jax_enable_x64", True)
    problem, E = _toy_problem(), radar_objective(kind="auto", draws=4, n=2)
    result = ds.optimise(problem, E=E, figures=False, judge=False, sensitivity=("rain_mm_h",))
    assert result.reference["answer_on"] == "E_ref"
    # clear weather: rain cannot go below 0, so the answers are taken at 0, delta and 2 delta
    moved = odd_shift(problem, E, "rain_mm_h")
    offsets = (0.0, 2.0, 4.0)
    answers = [ds.optimise(problem, E=moved(np.float64(b)), figures=False, judge=False).r_star[H] for b in offsets]
    assert answers[0] == result.r_star[H]
    slope = np.polyfit(offsets, answers, 1)[0]
    np.testing.assert_allclose(result.sensitivity["rain_mm_h"][H], slope, rtol=1e-9, atol=1e-12)
    assert result.sensitivity == ds.sensitivity(problem, result, ["rain_mm_h"], E=E)


def test_an_e_ref_answer_on_a_bound_is_held_there():
    jax.config.update("jax_enable_x64", True)
    problem, E = _toy_problem(), radar_objective(kind="auto", draws=4, n=2)
    result = ds.optimise(problem, E=E, figures=False, judge=False)
    on_bound = dataclasses.replace(result, solve=dataclasses.replace(result.solve, on_bound=True))
    assert ds.sensitivity(problem, on_bound, ["rain_mm_h", "traffic_speed_kmh"], E=E) == \
        {"rain_mm_h": {H: 0.0}, "traffic_speed_kmh": {H: 0.0}}


def _small(sensor: str, interval, **changes) -> ds.Problem:
    return ds.Problem(sensor=sensor, params={"hfov_deg": interval}, scenarios=["sc01", "sc03"], variants=2, **changes)


@pytest.mark.slow
def test_the_answer_lands_within_a_tenth_of_a_percent_of_the_dense_grid():
    problem = _small("radar", (5.0, 60.0))
    E = ds.objective(problem)
    events = []
    result = ds.optimise(problem, E=E, figures=False, judge=False, on_evaluation=events.append)
    programs = len(result.solve.sweep) + sum(result.solve.evaluations.values())
    assert programs <= 20 and result.solve.evaluations["gradient"] == 0
    dense = dense_grid_search(Evaluator(E).e_reference, (5.0, 60.0), 1.0)  # E_ref's compiled program
    assert result.reference["E_ref_star"] <= 1.001 * float(dense.E_hard.min())


@pytest.mark.slow
def test_dr_star_d_traffic_speed_is_within_ten_percent_of_re_solved_answers():
    # camera HFOV 20-120 deg: faster traffic narrows the best field of view (about -0.23 deg
    # per km/h), by far more than the answer's jumps of E_ref's fine structure
    problem = _small("camera", (20.0, 120.0))
    result = ds.optimise(problem, figures=False, judge=False, sensitivity=("traffic_speed_kmh",))
    ift = result.sensitivity["traffic_speed_kmh"][H]
    r = {kmh: ds.optimise(_small("camera", (20.0, 120.0), traffic_speed_offset_kmh=kmh), figures=False,
                          judge=False).r_star[H] for kmh in (-10.0, 10.0)}
    re_solved = (r[10.0] - r[-10.0]) / 20.0
    assert re_solved < -0.1
    np.testing.assert_allclose(ift, re_solved, rtol=0.10)
