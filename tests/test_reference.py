"""The reference objective E_ref (`Objective.reference`, `E(r, mode="reference")`): the hard
objective's expectation over Bernoulli detection draws with common random numbers."""

from __future__ import annotations

import math
from types import SimpleNamespace

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense import config as cfg
from diffsense import sensors as sensor
from diffsense.study._line_report import dense_check
from diffsense.runtime._errors import InputError
from diffsense.metrics import EstimatorConfig, make_objective
from diffsense.metrics._reference import reference_uniforms
from diffsense.sensors._laws import RadarDetection
from diffsense.solve import Evaluator
from diffsense.tracks import prediction_frames
from tests._toy_pipeline import TOY_GAIN, ToyPredictor, toy_scenes

H = "hfov_deg"
SWERLING = sensor.Radar(cfg.replace(sensor.load_config("radar"), detection=RadarDetection(law="swerling1")))


def radar_objective(radar=SWERLING, key=None, draws=4, n=1, kind="mean-field", **knobs):
    scenes, scenario = toy_scenes(n)
    frames = prediction_frames(scenes.num_frames)[:3]
    return make_objective(scenes, scenario, frames, radar, ToyPredictor(jnp.asarray(TOY_GAIN)), names=(H,),
                          key=key, estimator=EstimatorConfig(kind=kind, reference_draws=draws, **knobs), shard=False)


_reference = eqx.filter_jit(lambda o, r: o.reference({H: r}))
_hard = eqx.filter_jit(lambda o, r: o({H: r}, mode="hard"))
_e2 = eqx.filter_jit(lambda o, r, tau: o.e2({H: r}, tau))
_value_and_grad = eqx.filter_jit(lambda o, r, tau: jax.value_and_grad(lambda x: o.e2({H: x}, tau))(r))
# r and tau go in as arrays: `eqx.filter_jit` bakes a Python float into the program, one compile
# per point; as arrays, one per objective. Shared with the estimators' tests.
reference = lambda o, r: _reference(o, jnp.asarray(r))
hard = lambda o, r: _hard(o, jnp.asarray(r))
e2 = lambda o, r, tau: _e2(o, jnp.asarray(r), jnp.asarray(tau))
value_and_grad = lambda o, r, tau: _value_and_grad(o, jnp.asarray(r), jnp.asarray(tau))


@pytest.fixture(scope="module")
def swerling():
    return radar_objective()


def test_deterministic_law_reference_is_the_hard_objective():
    obj = radar_objective(sensor.Radar.from_toml())
    ref = reference(obj, 12.0)
    assert ref.draws.shape == (1,) and float(ref.e_se) == 0.0
    assert float(ref.e) == float(hard(obj, 12.0))
    called = eqx.filter_jit(lambda o, r: o({H: r}, mode="reference"))(obj, 12.0)
    assert float(called) == pytest.approx(float(ref.e), rel=1e-12)


def test_same_seed_same_reference_bit_for_bit(swerling):
    again = radar_objective()
    a, b = reference(swerling, 12.0), reference(again, 12.0)
    np.testing.assert_array_equal(np.asarray(a.draws), np.asarray(b.draws))
    assert float(a.e) == float(b.e)
    other = reference(radar_objective(key=jax.random.PRNGKey(5)), 12.0)
    assert not np.array_equal(np.asarray(other.draws), np.asarray(a.draws))  # the draws come from the key


def test_standard_error_of_the_draws(swerling):
    ref = reference(swerling, 8.0)  # a beam this narrow leaves the target on its edge
    draws = np.asarray(ref.draws, np.float64)
    assert draws.shape == (4,) and np.ptp(draws) > 0  # the draws differ: the law is random here
    assert float(ref.e2) == pytest.approx(draws.mean(), rel=1e-12)
    assert float(ref.e2_se) == pytest.approx(draws.std(ddof=1) / 2.0, rel=1e-9)
    assert float(ref.e) == pytest.approx(math.sqrt(draws.mean()), rel=1e-12)
    assert float(ref.e_se) == pytest.approx(draws.std(ddof=1) / 2.0 / (2 * math.sqrt(draws.mean())), rel=1e-9)


def test_draws_are_bernoulli_of_the_sensor_probability(swerling):
    # The mean of many draws' detections is p within 3 standard errors, vehicle by vehicle.
    p = np.asarray(swerling._sensor_detections({H: 12.0}, "hard").p_detect)
    k = 4000
    u = jax.vmap(lambda d: reference_uniforms(swerling.data.noise_key, d, p.shape[1:], p.dtype))(jnp.arange(k))
    share = np.mean(np.asarray(u) < p[None], axis=0)
    edge = (p > 0.05) & (p < 0.95)
    assert edge.sum() >= 5  # there are (frame, vehicle) pairs on the beam's edge
    se = np.sqrt(p * (1 - p) / k)
    assert np.all(np.abs(share - p)[edge] < 3 * se[edge] + 1e-12)


def test_hard_mode_is_the_median_detection(swerling):
    raw = np.asarray(swerling._sensor_detections({H: 12.0}, "hard").p_detect)
    assert np.any((raw > 0) & (raw < 1))
    median = np.asarray(swerling.detections({H: 12.0}, "hard").p_detect)
    np.testing.assert_array_equal(median, (raw >= 0.5).astype(raw.dtype))


def test_soft_gradient_matches_float64_central_differences(swerling):
    vg = eqx.filter_jit(lambda o, r: jax.value_and_grad(lambda x: o.e2({H: x}))(r))
    for r in (9.0, 16.0):
        value, grad = vg(swerling, jnp.asarray(r))
        h = 1e-4
        fd = (float(vg(swerling, jnp.asarray(r + h))[0]) - float(vg(swerling, jnp.asarray(r - h))[0])) / (2 * h)
        assert abs(float(grad)) > 1e-6
        np.testing.assert_allclose(float(grad), fd, rtol=1e-5)


def test_evaluator_memoises_the_reference_and_the_dense_check_uses_it(swerling):
    ev = Evaluator(swerling)
    first = ev.reference(12.0)
    assert ev.reference(12.0) is first and ev.reference_count == 1
    result = SimpleNamespace(r_star=12.0, bracket=(8.0, 16.0))
    dense = dense_check(ev, result, 8.0, 16.0, 4.0)
    assert dense["evaluations"] == 3 and dense["objective"] == "reference" and dense["reference_draws"] == 4
    best = min((8.0, 12.0, 16.0), key=ev.e_reference)
    assert dense["r_best"] == best and dense["E_ref_best"] == ev.e_reference(best)
    assert dense["E_ref_star"] == ev.e_reference(12.0) and dense["E_ref_star_se"] == float(first.e_se)
    assert ev.reference_count == 3 and ev.counts == {"soft": 0, "hard": 0}


def test_reference_draws_must_give_a_standard_error():
    with pytest.raises(InputError, match="reference_draws must be >= 2"):
        EstimatorConfig(reference_draws=1)


def test_other_draw_indices_are_independent_draws_of_the_same_scene(swerling):
    # E_ref's own draws are indices 0 ... K-1; indices from K on are fresh draws of the same scene,
    # so a block of 2K draws is the mean of the two K-blocks, and the default is the first block.
    on = eqx.filter_jit(lambda o, r, ids: o.reference({H: r}, draws=ids))
    own, fresh, both = (on(swerling, jnp.asarray(8.0), jnp.arange(a, b)) for a, b in ((0, 4), (4, 8), (0, 8)))
    np.testing.assert_array_equal(np.asarray(own.draws), np.asarray(reference(swerling, 8.0).draws))
    np.testing.assert_array_equal(np.asarray(both.draws), np.concatenate([np.asarray(own.draws), np.asarray(fresh.draws)]))
    assert not np.array_equal(np.asarray(fresh.draws), np.asarray(own.draws))
    assert float(both.e2) == pytest.approx(0.5 * (float(own.e2) + float(fresh.e2)), rel=1e-12)
