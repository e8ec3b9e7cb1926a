"""dr*/dtheta: the implicit-function-theorem derivative against finite differences (float64)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.solve import argmin, argmin_derivative

LOWER, UPPER = 0.0, 3.0


def e2_soft(r, theta):
    """A non-quadratic bowl whose minimum moves with theta = (a, b): E^2 > 0, r* interior."""
    a, b = theta
    return 1.0 + (r - jnp.sin(a) - 1.0) ** 2 + 0.1 * (r - b) ** 4 + 0.05 * jnp.exp(-r)


THETA = (jnp.asarray(0.7), jnp.asarray(1.2))


def _argmin_value(theta):
    return argmin(e2_soft, theta, LOWER, UPPER, xtol=1e-12)[0]


def test_implicit_derivative_matches_finite_differences_and_optimistix():
    r_star, on_bound = jax.jit(lambda th: argmin(e2_soft, th, LOWER, UPPER, xtol=1e-12))(THETA)
    explicit = jax.jit(lambda r, th: argmin_derivative(e2_soft, r, th))(r_star, THETA)
    implicit = jax.jit(jax.grad(_argmin_value))(THETA)
    h = 1e-5
    for i in range(2):
        plus = list(THETA)
        minus = list(THETA)
        plus[i] = plus[i] + h
        minus[i] = minus[i] - h
        fd = (float(_argmin_value(tuple(plus))) - float(_argmin_value(tuple(minus)))) / (2 * h)
        assert float(explicit[i]) == pytest.approx(fd, rel=1e-5, abs=1e-8)
        assert float(implicit[i]) == pytest.approx(float(explicit[i]), rel=1e-9, abs=1e-12)
    assert not bool(on_bound)
    # The optimum is a root of dE^2/dr.
    assert abs(float(jax.grad(e2_soft)(r_star, THETA))) < 1e-8


def test_zero_derivative_on_a_bound_and_no_nan():
    # Bracket [2, 3] lies right of the unconstrained optimum (~1.6): the minimum is r = 2.
    r_star, on_bound = jax.jit(lambda th: argmin(e2_soft, th, 2.0, UPPER))(THETA)
    assert float(r_star) == 2.0 and bool(on_bound)
    grad = jax.grad(lambda th: argmin(e2_soft, th, 2.0, UPPER)[0])(THETA)
    assert all(float(g) == 0.0 for g in grad)
    for r in (LOWER, UPPER):
        d = jax.jit(lambda r_, th: argmin_derivative(e2_soft, r_, th, on_bound=True))(r, THETA)
        assert all(float(x) == 0.0 for x in d)


def test_no_strict_minimum_gives_nan_not_garbage():
    # At a maximum of E^2 the implicit function theorem does not apply.
    d = argmin_derivative(lambda r, th: -((r - th) ** 2), jnp.asarray(1.0), jnp.asarray(1.0))
    assert np.isnan(float(d))


def test_follows_float32():
    theta = (jnp.float32(0.7), jnp.float32(1.2))
    r_star, _ = argmin(e2_soft, theta, jnp.float32(LOWER), jnp.float32(UPPER), xtol=1e-5)
    d = argmin_derivative(e2_soft, r_star, theta)
    assert r_star.dtype == jnp.float32 and d[0].dtype == jnp.float32
    assert np.isfinite(float(d[0])) and np.isfinite(float(d[1]))
