"""How far a many-parameter answer's r* would move with other traffic (`diffsense.study.
box_r_star_interval`, result.json's "r_star_ci" of a box solve).

- On an objective whose per-variant E^2 is quadratic in each parameter, the minimiser of the
  population's E is the mean of the variants' optima: over 60 samples each axis's 90 % interval
  (r* re-picked on each resample, `argmin_ci`) holds it in 80-97 %.
- Each axis holds the others at r*; the points stay in the bounds; variants identical within
  each scenario collapse every interval to r*'s value; a cost term (lambda x cost) moves the pick.
- A box solve asked for it (`BoxConfig(r_star_axes=True)`) with several variants per scenario
  writes one interval per parameter, with the points it took, and prints them beside r*; not
  asked, it evaluates no axis.
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
import pytest

import diffsense as ds
from diffsense.metrics import SceneSums, argmin_ci
from diffsense.metrics import make_objective
from diffsense.report import box_table
from diffsense.solve import BoxConfig
from diffsense.study import box_r_star_interval
from diffsense.tracks import prediction_frames
from tests._laws import THRESHOLD
from tests._toy_pipeline import TOY_GAIN, ToyPredictor, toy_scenes

STRATA = np.repeat([0, 1], 6)
BOUNDS = [(0.0, 10.0), (-5.0, 5.0)]


class _Quadratic:
    """Variant n's squared error at x: 1 + sum_i a_i (x_i - c_ni)^2 over one instant; E's axis
    minimiser on a reweighting w is the w-weighted mean of c_ni (its own check)."""

    def __init__(self, optima: np.ndarray, curvature=(1.0, 3.0)):
        self.optima, self.curvature = np.asarray(optima, np.float64), np.asarray(curvature)
        self.objective = type("Names", (), {"names": ("a.x", "b.y")})()
        self.asked: list[tuple[float, ...]] = []

    def scene_sums(self, x, of_reference=True) -> SceneSums:
        self.asked.append(tuple(np.asarray(x, np.float64)))
        sq = 1.0 + np.sum(self.curvature * (np.asarray(x) - self.optima) ** 2, axis=1)
        return SceneSums(sq=sq, instants=np.ones_like(sq), tracked_sq=sq[None], tracked=np.ones_like(sq)[None])


def _optima(seed=0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.normal(4.0, 1.0, STRATA.size), rng.normal(-1.0, 0.5, STRATA.size)])


def test_each_axis_interval_covers_the_population_minimiser_at_about_its_level():
    # the population minimiser of the quadratic model is the mean of the variants' optima (4, -1)
    held = []
    for seed in range(60):
        optima = _optima(seed)
        ev = _Quadratic(optima)
        x = optima.mean(axis=0)  # r* of the sample itself
        axes = box_r_star_interval(ev, x, BOUNDS, STRATA, of_reference=True, seed=seed)
        held.append([lo <= truth <= hi for ((lo, hi), _, _), truth in zip(axes, (4.0, -1.0))])
        for i, ((lo, hi), resolution, points) in enumerate(axes):
            assert lo <= x[i] <= hi and BOUNDS[i][0] <= lo and hi <= BOUNDS[i][1]
            assert resolution < (BOUNDS[i][1] - BOUNDS[i][0]) / 8 / 2 and points > 9  # refined where it ends
        for y in ev.asked:  # every point lies on an axis through r*, in the bounds
            assert np.sum(y != x) <= 1 and all(lo <= v <= hi for v, (lo, hi) in zip(y, BOUNDS))
    coverage = np.mean(held, axis=0)
    assert np.all((0.8 <= coverage) & (coverage <= 0.97)), coverage


def test_identical_variants_collapse_each_interval_to_r_star():
    optima = np.repeat(_optima()[[0, 6]], 6, axis=0)  # within each scenario, every variant alike
    x = optima.mean(axis=0)
    ev = _Quadratic(optima)
    axes = box_r_star_interval(ev, x, BOUNDS, STRATA, of_reference=True, seed=3)
    assert [a[0] for a in axes] == [[x[0], x[0]], [x[1], x[1]]]


def test_a_cost_term_moves_the_pick_to_the_cheap_end():
    optima = _optima()
    x = optima.mean(axis=0)
    plain = box_r_star_interval(_Quadratic(optima), x, BOUNDS, STRATA, of_reference=True, seed=0)
    priced = box_r_star_interval(_Quadratic(optima), x, BOUNDS, STRATA, of_reference=True, seed=0,
                                 offset_at=lambda y: 100.0 * y[0])  # a metre of J per 0.01 of a.x
    assert priced[0][0] == [BOUNDS[0][0], BOUNDS[0][0]] and plain[0][0][0] > BOUNDS[0][0]
    assert priced[1][0] == plain[1][0]  # the cost does not depend on b.y: its axis is as before


def test_argmin_ci_adds_the_offset_before_the_pick():
    strata = np.array([0, 0, 1, 1])
    sums = [SceneSums(sq=np.full(4, v), instants=np.ones(4), tracked_sq=np.full((1, 4), v), tracked=np.ones((1, 4)))
            for v in (4.0, 1.0, 2.25)]  # E 2, 1, 1.5 m
    assert argmin_ci([10.0, 20.0, 30.0], sums, strata) == (20.0, 20.0)
    assert argmin_ci([10.0, 20.0, 30.0], sums, strata, offset_m=np.array([0.0, 0.6, 0.0])) == (30.0, 30.0)
    with pytest.raises(ValueError):
        argmin_ci([10.0, 20.0, 30.0], sums, strata, offset_m=np.zeros(2))


def test_a_box_solve_asked_for_it_reports_r_star_s_interval_per_parameter():
    params = {"radar.range_m": (30.0, 200.0), "camera.width_px": (640.0, 3840.0)}
    tiny = BoxConfig(samples=4, starts=1, tau_schedule=(1.0,), max_steps=2, max_soft=3)
    problem = ds.Problem(sensor=["radar", "camera"], params=params, scenarios=["sc01"], sensor_config=dict(THRESHOLD),
                         box=tiny)
    scenes, scenario = toy_scenes(4)  # two scenarios of two variants each
    frames = prediction_frames(scenes.num_frames)[:3]
    E = make_objective(scenes, scenario, frames, problem.sensing.built, ToyPredictor(jax.numpy.asarray(TOY_GAIN)),
                       names=tuple(problem.params), key=jax.random.key(2, impl="rbg"))
    plain = ds.optimise(problem, E=E).to_json()  # not asked: no axis is evaluated
    assert plain["r_star_ci"] is None and plain["programs_run"]["intervals"] == {"hard": 0, "reference": 0}
    assert plain["E_ci"] is not None  # the answer's E still has its interval
    content = ds.optimise(problem.replace(box=dataclasses.replace(tiny, r_star_axes=True)), E=E).to_json()
    assert content["r_star"] == plain["r_star"]  # the interval does not move the answer
    assert set(content["r_star_ci"]) == set(params)
    for name, (lo, hi) in content["r_star_ci"].items():
        assert params[name][0] <= lo <= hi <= params[name][1]
        assert content["ci_method"]["r_star_points"][name] >= 9
    assert content["ci_method"]["r_star_caveat"] and content["programs_run"]["intervals"]["hard"] > 0
    printed = box_table(content)
    assert "r* with other traffic" in printed
    assert all(f"[{lo:.4g}, {hi:.4g}]" in printed for lo, hi in content["r_star_ci"].values())
