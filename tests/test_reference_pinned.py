"""E_ref's summary of its draws and the uniforms behind them (`metrics/_reference.py`), by hand:
the mean and standard errors of a few draws, the zero objective's edge, the streams that keep a
suite's members and the Monte-Carlo estimator's draws apart, the dtype they are drawn in, and
the detection events as the sensor itself gives them."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.metrics import make_objective
from diffsense.metrics._reference import MC_STREAM, DetectionEvents, detection_events, reference_uniforms, summarise
from diffsense.sensors import Suite, Weather
from diffsense.tracks import prediction_frames
from tests._toy_pipeline import TOY_GAIN, ToyPredictor, toy_scenes


def test_summary_of_two_draws():
    # draws 1 and 3: mean 2, sample sd sqrt(2), so se sqrt(2) / sqrt(2) = 1; E = sqrt(2) and by
    # the delta method its se is 1 / (2 sqrt(2)).
    s = summarise(jnp.array([1.0, 3.0]))
    assert float(s.e2) == 2.0 and float(s.e2_se) == pytest.approx(1.0, rel=1e-12)
    assert float(s.e) == pytest.approx(math.sqrt(2.0), rel=1e-12)
    assert float(s.e_se) == pytest.approx(1.0 / (2.0 * math.sqrt(2.0)), rel=1e-12)


def test_summary_below_one_and_of_one_draw():
    s = summarise(jnp.array([0.25, 0.25]))  # E^2 under 1 m^2 is still positive: E = 0.5
    assert float(s.e) == pytest.approx(0.5, rel=1e-12) and float(s.e_se) == 0.0
    one = summarise(jnp.array([4.0]))  # one draw: no spread to estimate, se 0
    assert (float(one.e), float(one.e2_se), float(one.e_se)) == (2.0, 0.0, 0.0)


def test_summary_of_a_zero_objective_is_zero_with_finite_gradients():
    s = summarise(jnp.zeros(3))
    assert (float(s.e), float(s.e_se)) == (0.0, 0.0)
    g = jax.grad(lambda d: summarise(d).e + summarise(d).e_se)(jnp.zeros(3))
    assert bool(jnp.all(jnp.isfinite(g)))


def test_uniforms_keep_members_and_streams_apart_in_the_given_dtype():
    keys = jax.random.split(jax.random.PRNGKey(0), 2)
    p = jnp.full((2, 5, 3), 0.5, jnp.float32)
    events = DetectionEvents(p_detect=[p, p], members=(0, 1), combine=lambda drawn: drawn)
    ref = events.uniforms(keys, jnp.asarray(0))
    mc = events.uniforms(keys, jnp.asarray(0), MC_STREAM)
    assert all(u.dtype == jnp.float32 and u.shape == (2, 5, 3) for u in ref + mc)
    assert not np.allclose(ref[0], ref[1]) and not np.allclose(mc[0], mc[1])  # members independent
    assert not np.allclose(ref[0], mc[0]) and not np.allclose(ref[1], mc[1])  # mc's own stream
    # each is the member's own stream of reference_uniforms
    np.testing.assert_array_equal(mc[1], reference_uniforms(keys, jnp.asarray(0), (5, 3), jnp.float32, 1, MC_STREAM))
    assert reference_uniforms(keys, jnp.asarray(0), (5, 3), jnp.float32).dtype == jnp.float32


def test_detection_events_are_the_sensors_own_probabilities_at_the_temperature():
    # One sensor: its soft p at the temperature multiplier given, and its hard p.
    from tests._toy_pipeline import toy_objective

    obj = toy_objective(n=1, instants=2)
    r = {"range_m": jnp.asarray(40.0)}
    soft = eqx.filter_jit(lambda o: (detection_events(o, r, "soft", 0.5).p_detect[0],
                                     o.detections(r, "soft", 0.5).p_detect))(obj)
    np.testing.assert_array_equal(*soft)
    assert float(jnp.min(jnp.abs(soft[0] - 0.5))) < 0.5  # some p strictly between 0 and 1


@pytest.mark.parametrize("mode", ["soft", "hard"])
def test_a_suites_events_are_its_members_views_in_the_objectives_weather(mode):
    # Each member's p as the suite's member_views gives it, at r, the mode, the temperature
    # multiplier and the variants' rain (so a dropped argument shows).
    from tests.test_suite_reference import CAMERA, NAMES, RADAR

    scenes, scenario = toy_scenes(1)
    obj = make_objective(scenes, scenario, prediction_frames(scenes.num_frames)[:2], Suite((RADAR, CAMERA)),
                         ToyPredictor(jnp.asarray(TOY_GAIN)), names=NAMES, shard=False,
                         weather=Weather(rain_mm_h=50.0))
    r = dict(zip(NAMES, (jnp.asarray(8.0), jnp.asarray(20.0))))

    @eqx.filter_jit
    def both(o):
        views = o._per_variant(r, lambda s, p, k, w: o.sensor.member_views(s, p, k, mode=mode, temperature=0.5,
                                                                           weather=w))
        return detection_events(o, r, mode, 0.5).p_detect, [d.p_detect for d, _ in views]

    events, views = both(obj)
    for got, want in zip(events, views, strict=True):
        np.testing.assert_array_equal(np.asarray(got), np.asarray(want))
