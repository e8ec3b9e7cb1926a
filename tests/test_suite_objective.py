"""The pieces of a suite problem composed: Suite -> Objective -> E + lambda * cost, its gradient
for every parameter against central differences (float64), and the box solve through an Evaluator.

The toy predictor stands in for the CS-LSTM: these tests check the composition and the
mathematics, not what a trained network makes of the tracks.
"""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np
import pytest

from diffsense.metrics import load_costs, make_cost, make_objective
from diffsense.sensors import Camera, Radar, Suite
from diffsense.solve import BoxConfig, BoxFunctions, Evaluator, box_solve
from diffsense.tracks import prediction_frames
from tests._toy_pipeline import TOY_GAIN, ToyPredictor, toy_scenes

LAWS = Path(__file__).resolve().parents[1] / "configs" / "sensors" / "laws"
# The threshold law (whichever the profile defaults to): the numbers below were measured under it.
SUITE = Suite((Radar.from_toml(LAWS / "radar_threshold.toml"), Camera.from_toml(LAWS / "camera_threshold.toml")))
LAMBDA = 0.01  # [m per EUR]


@pytest.fixture(scope="module")
def evaluator():
    """One compiled soft program (value and gradient) and one hard program, shared by the tests."""
    scenes, scenario = toy_scenes(2)
    frames = prediction_frames(scenes.num_frames)[:3]
    names = tuple(s.name for s in SUITE.param_specs())
    return Evaluator(make_objective(scenes, scenario, frames, SUITE, ToyPredictor(jax.numpy.asarray(TOY_GAIN)),
                                    names=names, key=jax.random.key(2, impl="rbg")))


def test_gradient_of_e_plus_cost_for_every_parameter(evaluator):
    names = evaluator.objective.names
    cost = make_cost(load_costs(), SUITE)
    cost_vg = jax.jit(jax.value_and_grad(cost))
    r0 = {"radar.hfov_deg": 60.0, "radar.vfov_deg": 12.0, "radar.range_m": 60.0, "radar.tx_power_dbm": 10.0,
          "radar.noise_figure_db": 6.0, "camera.hfov_deg": 50.0, "camera.range_m": 45.0,
          "camera.width_px": 900.0, "camera.baseline_m": 0.2,
          # The mounting: turned, moved back and aside from the defaults (0 deg, 4.2 / 2.5 m, 0 m).
          # The camera is turned far enough that its yaw matters: at -3 deg dE^2/dyaw is 1.5e-6 of
          # E^2 (4.9e-6 m^2/deg), and a central difference there measures E^2's last digits, not the
          # slope (1.6e-3 off with XLA at optimisation level 0, 3.1e-5 at its default level); at
          # -10 deg the slope is 3.4e-4 m^2/deg and the difference agrees to 5e-7 at either level.
          "radar.yaw_deg": 4.0, "radar.mount_x_m": 3.6, "radar.mount_y_m": 0.4,
          "camera.yaw_deg": -10.0, "camera.mount_x_m": 1.5, "camera.mount_y_m": -0.3}
    x0 = np.array([r0[n] for n in names])

    def j(x):  # E + lambda * cost and its gradient; E = sqrt(E^2), dE = dE^2 / (2 E)
        e2, g2 = evaluator.value_and_grad(x, 3.0)
        c, gc = cost_vg(dict(zip(names, x)))
        e = np.sqrt(e2)
        return e + LAMBDA * float(c), g2 / (2 * e) + LAMBDA * np.array([float(gc[n]) for n in names])

    value, grad = j(x0)
    assert np.isfinite(value)
    live = 0
    for i, name in enumerate(names):
        h = 1e-4 * abs(x0[i])
        up, down = x0.copy(), x0.copy()
        up[i], down[i] = x0[i] + h, x0[i] - h
        fd = (j(up)[0] - j(down)[0]) / (2 * h)
        np.testing.assert_allclose(grad[i], fd, rtol=1e-5, atol=1e-10, err_msg=name)
        live += abs(evaluator.value_and_grad(x0, 3.0)[1][i]) > 1e-8
    assert live >= 11  # E itself depends on most parameters here (the mounting included), not only the cost


def test_box_solve_through_the_evaluator(evaluator):
    names = evaluator.objective.names
    cost = make_cost(load_costs(), SUITE)
    fns = BoxFunctions.from_evaluator(evaluator, cost=cost)
    # Half to twice each default; the mounting (defaults 0 or on the envelope's front edge) moves
    # by up to 5 deg and 0.5 m instead.
    mounting = {"yaw_deg": (-5.0, 5.0), "mount_x_m": (-0.5, 0.0), "mount_y_m": (-0.5, 0.5)}
    bounds = {n: tuple(SUITE.spec(n).default + d for d in mounting[n.split(".")[1]]) if n.split(".")[1] in mounting
              else (0.5 * SUITE.spec(n).default, 2.0 * SUITE.spec(n).default) for n in names}
    before = dict(evaluator.counts)
    result = box_solve(fns, bounds, BoxConfig(samples=4, starts=1, tau_schedule=(2.0, 1.0), max_steps=3,
                                              cost_weight=LAMBDA))
    assert set(result.x_star) == set(names)
    lo, hi = np.array([bounds[n] for n in names]).T
    xs = np.array([e.x for e in result.history])
    assert (xs >= lo).all() and (xs <= hi).all()
    # Every evaluation the solve made is one program run (the earlier test's points are others).
    assert result.counts == {k: evaluator.counts[k] - before[k] for k in before}
    assert result.J_star == pytest.approx(result.E_hard + LAMBDA * result.cost)
    assert result.J_star <= min(e.value + LAMBDA * float(cost(dict(zip(names, e.x))))
                                for e in result.history if e.kind == "hard") + 1e-12
