"""Traffic speed as an ODD parameter: the scenes re-simulated at a traced speed offset, E and its
derivatives in it (float64 central differences), dr*/d(traffic_speed_kmh) against re-solved optima.

The problem is test_sensitivity's (the toy sensor whose noise grows with the square of its range,
the toy predictor) on the simulated scenario sc01, where E(range) has an interior minimum near
38 m.
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffsense as ds
from diffsense.scene import load_scenario, simulate_scenario
from diffsense.study import odd_shift, traffic_scenes
from tests._toy_pipeline import TOY_GAIN, ToyPredictor
from tests.test_sensitivity import RainyToy, _result

ROOT = Path(__file__).resolve().parents[1]
R_M = 38.0  # next to the interior minimum


@pytest.fixture(scope="module")
def setup():
    jax.config.update("jax_enable_x64", True)
    problem = ds.Problem(sensor=RainyToy(), predictor=ToyPredictor(jnp.asarray(TOY_GAIN)),
                         params={"range_m": (10.0, 120.0)}, scenarios=("sc01",), variants=1,
                         prediction_stride_frames=10)
    E = ds.objective(problem)
    moved = odd_shift(problem, E, "traffic_speed_kmh")

    def e2(r, shift):
        return moved(shift).e2({"range_m": r}, 1.0)

    g = jax.grad(e2, 0)
    # One program for every check: E^2, dE^2/dr, dE^2/dtheta, d2E^2/dr dtheta and the scenes.
    f = jax.jit(lambda r, s: (e2(r, s), g(r, s), jax.grad(e2, 1)(r, s), jax.grad(g, 1)(r, s),
                              moved(s).data.scenes))
    return problem, E, f


def test_zero_shift_is_the_problem_itself(setup):
    _, E, f = setup
    e2, *_, scenes = f(R_M, 0.0)
    np.testing.assert_allclose(e2, E.e2({"range_m": R_M}), rtol=1e-12)
    np.testing.assert_array_equal(scenes.present, E.data.scenes.present)
    np.testing.assert_allclose(scenes.x_m, E.data.scenes.x_m, rtol=0, atol=1e-9)


def test_cross_derivative_matches_central_differences(setup):
    *_, f = setup
    h = 1e-4  # E^2 has kinks in the speed (the simulation's discrete events): a small step stays between them
    cross = float(f(R_M, 0.0)[3])
    fd = (float(f(R_M, h)[1]) - float(f(R_M, -h)[1])) / (2 * h)
    assert abs(cross) > 1e-3  # the speed matters here
    np.testing.assert_allclose(cross, fd, rtol=1e-5)
    dE2_ds = float(f(R_M, 0.0)[2])
    np.testing.assert_allclose(dE2_ds, (float(f(R_M, h)[0]) - float(f(R_M, -h)[0])) / (2 * h), rtol=1e-5)


@pytest.mark.parametrize("shift_kmh", [-30.0, 60.0])
def test_finite_over_the_documented_speed_range(setup, shift_kmh):
    """sc01's slowest vehicle starts at 35 km/h: -30 km/h leaves it 5 km/h; +60 km/h takes the
    ego to 115 km/h."""
    _, E, f = setup
    *out, scenes = f(R_M, shift_kmh)
    assert np.all(np.isfinite(out)), out
    ego_s = scenes.s_m[0, :, 0]
    travelled = float(ego_s[-1] - ego_s[0]) - float(E.data.scenes.s_m[0, -1, 0] - E.data.scenes.s_m[0, 0, 0])
    assert np.sign(travelled) == np.sign(shift_kmh) and abs(travelled) > 0.5 * abs(shift_kmh) / 3.6 * 20.0


def test_an_offset_that_stops_a_vehicle_is_refused():
    with pytest.raises(ds.InputError, match=r"stops its slowest vehicle \(start speed 35 km/h\)"):
        simulate_scenario(load_scenario("sc01"), 1, 0, speed_offset_kmh=-35.0)


@pytest.mark.slow
def test_implicit_derivative_matches_re_solved_optima(setup):
    problem, E, f = setup

    def re_solve(shift, lo=30.0, hi=50.0):
        """The stationary point of the soft E^2 by bisection on its derivative, to 1e-10 m."""
        assert f(lo, shift)[1] < 0 < f(hi, shift)[1]
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if f(mid, shift)[1] < 0 else (lo, mid)
        return 0.5 * (lo + hi)

    r_star = re_solve(0.0)
    ift = ds.sensitivity(problem, _result(r_star), ["traffic_speed_kmh"], E=E)["traffic_speed_kmh"]["range_m"]
    h = 0.1  # inside the smooth piece around the problem's speed (kinks lie within 0.5 km/h of it)
    fd = (re_solve(h) - re_solve(-h)) / (2 * h)
    assert abs(fd) > 0.01
    np.testing.assert_allclose(ift, fd, rtol=0.05)
    on_bound = ds.sensitivity(problem, _result(r_star, on_bound=True), ["traffic_speed_kmh"], E=E)
    assert on_bound["traffic_speed_kmh"]["range_m"] == 0.0


def test_sensitivity_to_the_speed_is_the_implicit_function_theorems(setup):
    """-(d2E^2/dr dtheta) / (d2E^2/dr2) at the reported r*, the curvature by central differences
    of dE^2/dr (the slow test below checks it against re-solved optima)."""
    problem, E, f = setup
    h = 1e-4
    curvature = (float(f(R_M + h, 0.0)[1]) - float(f(R_M - h, 0.0)[1])) / (2 * h)
    assert curvature > 0
    got = ds.sensitivity(problem, _result(R_M), ["traffic_speed_kmh"], E=E)
    assert list(got) == ["traffic_speed_kmh"]
    np.testing.assert_allclose(got["traffic_speed_kmh"]["range_m"], -float(f(R_M, 0.0)[3]) / curvature, rtol=1e-5)
    assert ds.sensitivity(problem, _result(R_M), ["traffic_speed_kmh"]) == got  # E built from the problem


def test_the_re_simulated_scenes_are_in_the_objectives_precision(setup):
    problem, E, _ = setup
    scenes = traffic_scenes(problem, E.spec, E.sensor, jnp.float32)[0](jnp.float32(0.0))
    assert scenes.x_m.dtype == jnp.float32 and E.data.scenes.x_m.dtype == jnp.float64
    np.testing.assert_allclose(scenes.x_m, E.data.scenes.x_m, rtol=0, atol=1e-3)
