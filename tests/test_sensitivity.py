"""dr*/dtheta by the implicit function theorem against finite differences of re-solved r*.

The test sensor is the toy one of `_toy_pipeline` with a reach that rain shortens,
range / (1 + 0.02 rain), and noise growing with the square of its range: E(range) has an interior
minimum near 47 m that moves with the rain.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffsense as ds
from diffsense.metrics import make_objective
from diffsense.sensors import Weather
from diffsense.sensors._datatypes import Detections
from diffsense.solve import SolveConfig, SolveResult
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


def test_unknown_odd_parameter_is_one_line():
    with pytest.raises(ds.InputError, match="no sensitivity to 'snow_cm'"):
        ds.sensitivity(ds.Problem(), _result(30.0), ["snow_cm"])
