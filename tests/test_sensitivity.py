"""`ds.sensitivity`: dr*/dtheta by the implicit function theorem, against finite differences of
re-solved optima, and against -(d2E^2/dr dtheta) / (d2E^2/dr2) from float64 central differences
of E^2 itself at the r and temperature it is taken at; when it answers 0 or None; its refusals.

The test sensor is the toy one of `_toy_pipeline` with a reach that rain shortens,
range / (1 + 0.02 rain), and noise growing with the square of its range: E(range) has an interior
minimum near 47 m that moves with the rain. The points below are where the candidates (the last
level's r or the reported r*, the last temperature or the first) give clearly different answers.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffsense as ds
from diffsense.metrics import make_objective
from diffsense.sensors import Detections, Weather
from diffsense.solve import LevelResult, SolveResult
from diffsense.study import ODD_PARAMETERS, WEATHER_PARAMETERS, check_theta, odd_shift
from diffsense.tracks import prediction_frames
from tests._toy_pipeline import NOISE_M, TOY_GAIN, ToyPredictor, ToySensor, toy_scenes

RAIN = 5.0


class RainyToy(ToySensor):
    kind: ClassVar[str] = "rainytoy"

    def _detect(self, scene, r, noise, mode, temperature, weather):
        dist = jnp.abs(scene.x_m - scene.x_m[..., :1])
        margin = r["range_m"] / (1.0 + 0.02 * weather.rain_mm_h) - dist
        p = jax.nn.sigmoid(margin / (2.0 * temperature)) if mode == "soft" else (margin > 0).astype(dist.dtype)
        p = p.at[..., 0].set(1.0)
        eps = jax.random.normal(noise, (2, *scene.x_m.shape), dist.dtype)
        scale = NOISE_M * (1.0 + (r["range_m"] / 30.0) ** 2)
        return Detections(p_detect=p, x_m=(scene.x_m + scale * eps[0]).at[..., 0].set(scene.x_m[..., 0]),
                          y_m=(scene.y_m + scale * eps[1]).at[..., 0].set(scene.y_m[..., 0]))


def _objective(rain: float):
    scenes, scenario = toy_scenes(3)
    return make_objective(scenes, scenario, prediction_frames(scenes.num_frames), RainyToy(),
                          ToyPredictor(jnp.asarray(TOY_GAIN)), names=("range_m",), weather=Weather(rain_mm_h=rain))


_grad = eqx.filter_jit(jax.grad(lambda r, E: E.e2({"range_m": r}, 1.0)))


def _re_solve(E, lo=42.0, hi=60.0) -> float:
    """The stationary point of the soft E^2 by bisection on its derivative, to 1e-10 m."""
    assert _grad(lo, E) < 0 < _grad(hi, E)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _grad(mid, E) < 0 else (lo, mid)
    return 0.5 * (lo + hi)


def _result(r_star: float, on_bound: bool = False):
    solve = SolveResult(r_star=r_star, E_soft_star=0.0, E_hard_star=0.0, sweep=(), evaluations={}, on_bound=on_bound,
                        bracket=(10.0, 120.0), tau_schedule=(1.0,), levels=(), notes=(), interval=(10.0, 120.0),
                        wall_s={})
    return ds.Result(sensor="rainytoy", params={"range_m": (10.0, 120.0)}, units={"range_m": "m"},
                     r_star={"range_m": r_star}, E_hard_star=0.0, E_soft_star=0.0, solve=solve, programs_run={},
                     wall_s={}, scenarios=(), config={})


H = 1e-3  # [m] and [mm/h]: float64 differences of E^2 ~ 1e2 keep 1e-7 of the curvatures below


@pytest.fixture(scope="module")
def setup():
    jax.config.update("jax_enable_x64", True)
    E = _objective(RAIN)
    problem = ds.Problem(sensor=RainyToy(), params={"range_m": (10.0, 120.0)})

    @jax.jit
    def e2(r, rain, tau):
        moved = eqx.tree_at(lambda o: o.weather.rain_mm_h, E, E.weather.rain_mm_h + (rain - RAIN))
        return moved.e2({"range_m": r}, tau)

    return problem, E, e2


def _by_differences(e2, r: float, tau: float) -> float:
    curvature = (e2(r + H, RAIN, tau) - 2 * e2(r, RAIN, tau) + e2(r - H, RAIN, tau)) / H**2
    cross = (e2(r + H, RAIN + H, tau) - e2(r + H, RAIN - H, tau) - e2(r - H, RAIN + H, tau)
             + e2(r - H, RAIN - H, tau)) / (4 * H * H)
    assert curvature > 0
    return float(-cross / curvature)


def _with(result: ds.Result, *, taus=(), levels=(), on_bound=False) -> ds.Result:
    solve = dataclasses.replace(result.solve, tau_schedule=taus, levels=levels, on_bound=on_bound)
    return dataclasses.replace(result, solve=solve)


def _level(tau: float, r: float, bound: int = 0) -> LevelResult:
    return LevelResult(tau=tau, r=r, gradient_evaluations=7, bound=bound, converged=True)


def test_at_the_last_levels_r_and_the_last_temperature(setup):
    """Reported r* 45 m; last level r 40 m at tau 4 (the first, tau 1, was at 30 m)."""
    problem, E, e2 = setup
    result = _with(_result(45.0), taus=(1.0, 4.0), levels=(_level(1.0, 30.0), _level(4.0, 40.0)))
    got = ds.sensitivity(problem, result, ["rain_mm_h", "fog_visibility_m"], E=E)
    assert list(got) == ["rain_mm_h", "fog_visibility_m"]
    assert list(got["rain_mm_h"]) == ["range_m"]
    expected = _by_differences(e2, 40.0, 4.0)
    np.testing.assert_allclose(expected, 0.5086, atol=1e-3)  # the other candidates: 0.39, 0.70, 0.56
    np.testing.assert_allclose(got["rain_mm_h"]["range_m"], expected, rtol=1e-4)
    assert got["fog_visibility_m"] == {"range_m": 0.0}  # this sensor ignores fog
    assert isinstance(got["rain_mm_h"]["range_m"], float)


def test_without_levels_at_the_reported_r_star_and_temperature_1(setup):
    problem, E, e2 = setup
    got = ds.sensitivity(problem, _with(_result(45.0)), ["rain_mm_h"], E=E)
    expected = _by_differences(e2, 45.0, 1.0)
    np.testing.assert_allclose(expected, 0.6513, atol=1e-3)
    np.testing.assert_allclose(got["rain_mm_h"]["range_m"], expected, rtol=1e-4)
    at_half = ds.sensitivity(problem, _with(_result(45.0), taus=(0.5,)), ["rain_mm_h"], E=E)
    np.testing.assert_allclose(at_half["rain_mm_h"]["range_m"], _by_differences(e2, 45.0, 0.5), rtol=1e-4)


@pytest.mark.parametrize("bound", [-1, 1])
def test_on_a_bound_or_a_last_level_on_its_brackets_edge_it_is_held(setup, bound):
    problem, E, _ = setup
    result = _with(_result(45.0), taus=(1.0,), levels=(_level(1.0, 45.0, bound),))
    assert ds.sensitivity(problem, result, ["rain_mm_h"], E=E) == {"rain_mm_h": {"range_m": 0.0}}
    inside = _with(_result(45.0), taus=(1.0,), levels=(_level(1.0, 45.0, bound), _level(1.0, 45.0)))
    assert ds.sensitivity(problem, inside, ["rain_mm_h"], E=E)["rain_mm_h"]["range_m"] > 0.5
    on_bound = _with(_result(45.0), taus=(1.0,), levels=(_level(1.0, 45.0),), on_bound=True)  # of the interval
    assert ds.sensitivity(problem, on_bound, ["rain_mm_h"], E=E) == {"rain_mm_h": {"range_m": 0.0}}


def test_none_where_the_soft_objective_is_concave(setup):
    """At 20 m and tau 0.5 d2E^2/dr2 < 0: no strict minimum, so no derivative (fog's too)."""
    problem, E, e2 = setup
    assert e2(20.0 + H, RAIN, 0.5) - 2 * e2(20.0, RAIN, 0.5) + e2(20.0 - H, RAIN, 0.5) < 0
    result = _with(_result(45.0), taus=(0.5,), levels=(_level(0.5, 20.0),))
    assert ds.sensitivity(problem, result, ["rain_mm_h", "fog_visibility_m"], E=E) == {
        "rain_mm_h": {"range_m": None}, "fog_visibility_m": {"range_m": None}}


def test_odd_shift_moves_every_variants_weather_by_the_shift(setup):
    problem, E, _ = setup
    for theta in WEATHER_PARAMETERS:
        moved = odd_shift(problem, E, theta)(jnp.asarray(2.5))
        np.testing.assert_array_equal(getattr(moved.weather, theta), getattr(E.weather, theta) + 2.5)
        other, = (t for t in WEATHER_PARAMETERS if t != theta)
        np.testing.assert_array_equal(getattr(moved.weather, other), getattr(E.weather, other))
    assert ODD_PARAMETERS == ("rain_mm_h", "fog_visibility_m", "traffic_speed_kmh")


@pytest.mark.slow
def test_implicit_derivative_matches_re_solved_optima():
    E = _objective(RAIN)
    r_star = _re_solve(E)
    problem = ds.Problem(sensor=RainyToy(), params={"range_m": (10.0, 120.0)})
    ift = ds.sensitivity(problem, _result(r_star), ["rain_mm_h", "fog_visibility_m"], E=E)
    h = 0.5
    fd = (_re_solve(_objective(RAIN + h)) - _re_solve(_objective(RAIN - h))) / (2 * h)
    assert fd > 0.1  # rain shortens the reach: the best range grows
    np.testing.assert_allclose(ift["rain_mm_h"]["range_m"], fd, rtol=0.05)
    assert ift["fog_visibility_m"]["range_m"] == 0.0  # this sensor ignores fog
    on_bound = ds.sensitivity(problem, _result(r_star, on_bound=True), ["rain_mm_h"], E=E)
    assert on_bound["rain_mm_h"]["range_m"] == 0.0


def test_refusals_name_their_culprit(setup, tmp_path):
    problem, E, _ = setup
    (tmp_path / "r.csv").touch()
    with pytest.raises(ds.InputError, match="no sensitivity to 'snow_cm'.*rain_mm_h, fog_visibility_m, traffic_speed_kmh"):
        check_theta(problem, ["rain_mm_h", "snow_cm", "hail"])  # the first unknown, and the known ones
    with pytest.raises(ds.InputError, match="'hail'"):
        odd_shift(problem, E, "hail")
    recorded = problem.replace(scenes=f"highd:{tmp_path / 'r.csv'}")
    check_theta(recorded, list(WEATHER_PARAMETERS))
    with pytest.raises(ds.InputError, match="no sensitivity to traffic_speed_kmh for recorded scenes"):
        check_theta(recorded, ["rain_mm_h", "traffic_speed_kmh"])
    check_theta(problem, list(ODD_PARAMETERS))
    two = dataclasses.replace(_result(45.0), r_star={"range_m": 45.0, "gain": 1.0})
    with pytest.raises(ds.InputError, match="one-parameter problems"):
        ds.sensitivity(problem, two, ["rain_mm_h"], E=E)
    with pytest.raises(ds.InputError, match="'snow_cm'"):
        ds.sensitivity(problem, two, ["snow_cm"], E=E)  # theta is checked first


def test_in_the_objectives_precision(setup):
    """A float32 objective beside 64-bit JAX: r* enters as float32, so the answer is a float32
    number (a float64 r* would promote the derivative's program to float64), the float32 central
    differences' (its noise draws are float32's, so its E is not the float64 one's)."""
    problem, _, _ = setup
    scenes, scenario = toy_scenes(3)
    scenes = jax.tree.map(lambda a: a.astype(jnp.float32) if jnp.issubdtype(a.dtype, jnp.floating) else a, scenes)
    E32 = make_objective(scenes, scenario, prediction_frames(scenes.num_frames), RainyToy(),
                         ToyPredictor(jnp.asarray(TOY_GAIN, jnp.float32)), names=("range_m",),
                         weather=Weather(rain_mm_h=RAIN))
    got = ds.sensitivity(problem, _with(_result(45.0)), ["rain_mm_h"], E=E32)["rain_mm_h"]["range_m"]
    assert E32.dtype == jnp.float32 and float(np.float32(got)) == got

    @jax.jit
    def e2(r, rain):  # float32 differences: a wider step keeps rounding to ~1e-3 of the curvature
        moved = eqx.tree_at(lambda o: o.weather.rain_mm_h, E32, E32.weather.rain_mm_h + (rain - RAIN))
        return moved.e2({"range_m": r}, 1.0)

    h, r, rain = np.float32(0.05), np.float32(45.0), np.float32(RAIN)
    curvature = (e2(r + h, rain) - 2 * e2(r, rain) + e2(r - h, rain)) / h**2
    cross = (e2(r + h, rain + h) - e2(r + h, rain - h) - e2(r - h, rain + h) + e2(r - h, rain - h)) / (4 * h * h)
    np.testing.assert_allclose(got, -float(cross) / float(curvature), rtol=1e-2)
