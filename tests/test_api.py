"""The public API: `ds.objective` under jit/grad/vmap (its gradient against float64 central
differences), `ds.optimise`, and the two protocols a user plugs into (a custom sensor and a
constant-velocity predictor, defined here). What `ds.Problem` accepts: tests/test_problem.py.

The CS-LSTM is randomly initialised: these tests check the API and the mathematics, which do
not depend on what the network learnt.
"""

from __future__ import annotations

import json
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffsense as ds
from diffsense.predictors import CSLSTM_SPEC, InputSpec, PredictorInputs
from tests._laws import THRESHOLD
from tests._toy_pipeline import ToySensor

ROOT = Path(__file__).resolve().parents[1]


class ConstantVelocity(eqx.Module):
    """A predictor through the protocol: the target keeps its velocity of the last second."""

    spec: InputSpec = eqx.field(static=True, default=CSLSTM_SPEC)

    def __call__(self, inputs: PredictorInputs):
        per_s = self.spec.rate_hz
        velocity = (inputs.hist[:, -1] - inputs.hist[:, -1 - int(per_s)])  # [B, 2] over 1 s
        t = jnp.arange(1, self.spec.future_points + 1, dtype=inputs.hist.dtype) / per_s
        return inputs.hist[:, -1][:, None] + velocity[:, None] * t[None, :, None]


@pytest.fixture(scope="module")
def random_cslstm():
    return ds.predictors.init_predictor(maneuvers=False, seed=0)


@pytest.fixture(scope="module")
def radar(random_cslstm):
    problem = ds.Problem(sensor="radar", params={"hfov_deg": (30.0, 180.0), "range_m": (30.0, 200.0)},
                         scenarios=["sc01"], variants=2, seed=0, predictor=random_cslstm,
                         prediction_stride_frames=20, predictor_dtype="float64",  # float64 throughout for FD
                         sensor_config=THRESHOLD["radar"])  # the threshold law's mean-field E: smooth
    return ds.objective(problem)


@eqx.filter_jit
def _value(E, r, tau):
    return E(r, tau=tau)


@eqx.filter_jit
def _value_and_grad(E, r, tau):
    return jax.value_and_grad(lambda r: E(r, tau=tau))(r)


def _arrays(r):
    """r's values as arrays: `eqx.filter_jit` bakes a Python float into the program, and every
    finite-difference point would compile one of its own."""
    return {k: jnp.asarray(v) for k, v in r.items()}


def _central(E, r, name, h, tau=1.0):
    up, down = dict(r), dict(r)
    up[name], down[name] = r[name] + h, r[name] - h
    return (float(_value(E, _arrays(up), tau)) - float(_value(E, _arrays(down), tau))) / (2 * h)


def test_dict_gradient_equals_central_differences_radar(radar):
    r = {"hfov_deg": 50.0, "range_m": 80.0}
    value, grad = _value_and_grad(radar, _arrays(r), 2.0)
    assert set(grad) == set(r) and np.isfinite(float(value))
    for name, h in (("hfov_deg", 1e-3), ("range_m", 1e-3)):
        np.testing.assert_allclose(float(grad[name]), _central(radar, r, name, h, tau=2.0), rtol=1e-5, atol=1e-10)


def test_objective_under_jit_and_vmap(radar):
    hfov = jnp.array([40.0, 90.0])
    batch = jax.jit(jax.vmap(lambda h: radar({"hfov_deg": h, "range_m": 100.0})))(hfov)
    jitted = jax.jit(radar)
    each = [float(jitted({"hfov_deg": h, "range_m": 100.0})) for h in hfov]
    np.testing.assert_allclose(np.asarray(batch), each, rtol=1e-10)
    hard = jax.jit(radar, static_argnames="mode")({"hfov_deg": 40.0}, mode="hard")
    assert np.isfinite(float(hard)) and float(hard) > 0.0


def test_custom_sensor_and_constant_velocity_predictor_end_to_end():
    problem = ds.Problem(sensor=ToySensor(), params={"range_m": (10.0, 150.0)}, scenarios=["sc01"],
                         variants=1, predictor=ConstantVelocity(), prediction_stride_frames=20)
    result = ds.optimise(problem)
    (name, r_star), = result.r_star.items()
    assert name == "range_m" and 10.0 <= r_star <= 150.0
    assert result.E_hard_star <= min(p.E_hard for p in result.sweep)
    content = result.to_json()
    assert content["sensor"] == "toy" and content["r_star"] == {"range_m": r_star}
    json.dumps(content)  # JSON-ready
    # Seeing farther never hurts a constant-velocity predictor fed by a noise-free-enough sensor:
    # the blind end of the interval must not be the answer.
    assert r_star > 10.0


def test_registered_sensor_by_name():
    ds.sensors.register("toy", ToySensor)
    assert "toy" in ds.sensors.sensor_names()
    assert ds.Problem(sensor="toy", params={"range": (10, 20)}).params == {"range_m": (10.0, 20.0)}
