"""The estimators' building blocks (`metrics/_estimators.py`) against independent values: the
binary-Concrete sample in its odds form, its threshold a Bernoulli(p) draw, the Monte-Carlo
uniforms strictly inside (0, 1), and the config's bounds on their edges."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.errors import InputError
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
