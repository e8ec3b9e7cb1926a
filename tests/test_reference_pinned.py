"""E_ref's summary of its draws and the uniforms behind them (`metrics/_reference.py`), by hand:
the mean and standard errors of a few draws, the zero objective's edge, the streams that keep a
suite's members and the Monte-Carlo estimator's draws apart, and the dtype they are drawn in."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.metrics._reference import MC_STREAM, DetectionEvents, reference_uniforms, summarise


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
