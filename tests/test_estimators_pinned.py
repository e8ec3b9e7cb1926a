"""The estimators' building blocks (`metrics/_estimators.py`) against independent values: the
binary-Concrete sample in its odds form, its threshold a Bernoulli(p) draw, the Monte-Carlo
uniforms strictly inside (0, 1), the config's bounds on their edges, and the Monte-Carlo
estimator against E_ref."""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.runtime._errors import InputError
from diffsense.metrics._estimators import EstimatorConfig, mc_uniforms, relaxed_bernoulli


@pytest.mark.parametrize("p, u, temperature", [(0.3, 0.8, 0.5), (0.9, 0.05, 2.0), (0.5, 0.5, 0.1)])
def test_relaxed_bernoulli_is_the_binary_concrete_sample(p, u, temperature):
    # Written with odds instead of logits: 1 / (1 + ((1 - p)(1 - u) / (p u))^(1 / lambda)).
    by_hand = 1.0 / (1.0 + ((1.0 - p) * (1.0 - u) / (p * u)) ** (1.0 / temperature))
    sample = relaxed_bernoulli(jnp.asarray(p), jnp.asarray(u), temperature)
    assert float(sample) == pytest.approx(by_hand, rel=1e-12)


def test_a_relaxed_bernoulli_sample_above_one_half_is_a_bernoulli_p_draw():
    # P(sample > 1/2) = P(logit u > -logit p) = p for uniform u, at any temperature.
    u = mc_uniforms(jax.random.key(1), 20_000, (), jnp.float64)
    for p in (0.1, 0.6):
        hits = np.asarray(relaxed_bernoulli(jnp.full(u.shape, p), u, 0.3) > 0.5)
        assert abs(hits.mean() - p) < 3.0 * np.sqrt(p * (1 - p) / hits.size)


def test_the_monte_carlo_uniforms_stay_strictly_inside_0_and_1():
    # 2^24 float32 draws: JAX's uniforms are multiples of 2^-23 = eps, so without the bounds a 0
    # (or, with an upper bound past 1, a 1) turns up about once in this many; log u and
    # log1p(-u) then give -inf.
    eps = float(jnp.finfo(jnp.float32).eps)
    u = np.asarray(mc_uniforms(jax.random.key(0), 1, (1 << 24,), jnp.float32))
    assert u.shape == (1, 1 << 24) and u.dtype == np.float32
    assert u.min() >= eps and u.max() <= 1.0 - eps


def test_estimator_config_bounds_on_their_edges():
    assert EstimatorConfig(samples=1, reference_draws=2).reference_draws == 2
    with pytest.raises(InputError, match="reference_draws must be >= 2"):
        EstimatorConfig(reference_draws=1)
    with pytest.raises(InputError, match="estimator samples must be >= 1"):
        EstimatorConfig(samples=0)
    for name in ("relax_temperature", "reference_temperature"):
        assert getattr(EstimatorConfig(**{name: 1e-9}), name) == 1e-9
        with pytest.raises(InputError, match=f"^{name} must be > 0, got 0.0$"):
            EstimatorConfig(**{name: 0.0})


def test_monte_carlo_estimates_the_reference_where_mean_field_is_biased():
    # A beam of 8 deg: the target's detections are random events. 64 Monte-Carlo samples, drawn
    # cold (each nearly a hard draw) from their own uniforms, and E_ref's 64 draws estimate the
    # same expectation: within 3 combined standard errors. Mean-field, E^2 of the averaged
    # detections, is biased here by more than 3 of them.
    from tests.test_reference import H, radar_objective

    ref = eqx.filter_jit(lambda o: o.reference({H: 8.0}))(radar_objective(draws=64))
    se = float(np.std(np.asarray(ref.draws), ddof=1)) / 8.0
    e2 = eqx.filter_jit(lambda o: o.e2({H: 8.0}, 1.0))
    mc = float(e2(radar_objective(kind="mc", samples=64, relax_temperature=1e-4)))
    mean_field = float(e2(radar_objective(kind="mean-field")))
    assert abs(mc - float(ref.e2)) < 3.0 * math.sqrt(2.0) * se
    assert abs(mean_field - float(ref.e2)) > 3.0 * math.sqrt(2.0) * se


def test_monte_carlo_value_written_out_sample_by_sample():
    # Each sample relaxes the soft detections at the temperature multiplier tau with its own row
    # of fixed uniforms (binary Concrete, in its odds form here); E^2 is the samples' mean.
    from diffsense.metrics._coverage import p_tracked
    from tests._toy_pipeline import toy_objective

    lam, tau = 0.3, 0.5
    mc = toy_objective(n=2, instants=4, fill="interp", key=jax.random.PRNGKey(1),
                       estimator=EstimatorConfig(kind="mc", samples=3, relax_temperature=lam))

    @eqx.filter_jit
    def by_hand(obj):
        det = obj.detections({"range_m": 40.0}, "soft", tau)
        p = jnp.clip(det.p_detect, 1e-12, 1.0 - 1e-12)
        total = 0.0
        for k in range(3):
            u = obj.data.mc_uniform[:, k]
            odds = ((1.0 - p) * (1.0 - u) / (p * u)) ** (1.0 / lam)
            d = dataclasses.replace(det, p_detect=1.0 / (1.0 + odds))
            total = total + obj._question(obj._predict(d), p_tracked(obj._target_window(d)))
        return total / 3

    got = eqx.filter_jit(lambda o: o.e2({"range_m": 40.0}, tau))(mc)
    np.testing.assert_allclose(float(got), float(by_hand(mc)), rtol=1e-9)
