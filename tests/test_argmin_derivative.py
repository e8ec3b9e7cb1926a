"""dr*/dtheta, how the best parameter moves with a scenario parameter: `argmin_derivative` (the
implicit function theorem's formula) and jax.grad through `argmin` (optimistix's implicit
adjoint) against float64 central differences of the argmin itself; zero on a bound, NaN where
there is no strict minimum. And `argmin` itself: the minimum downhill of its start, its default
tolerance, its dtype, its step cap."""

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


def test_follows_float32():
    theta = (jnp.float32(0.7), jnp.float32(1.2))
    r_star, _ = argmin(e2_soft, theta, jnp.float32(LOWER), jnp.float32(UPPER), xtol=1e-5)
    d = argmin_derivative(e2_soft, r_star, theta)
    assert r_star.dtype == jnp.float32 and d[0].dtype == jnp.float32
    assert np.isfinite(float(d[0])) and np.isfinite(float(d[1]))


def _two_minima(r, theta):
    """E^2 = (r - 0.5)^2 (r - 2.5)^2 + theta: minima at 0.5 and 2.5, a maximum at 1.5."""
    return (r - 0.5) ** 2 * (r - 2.5) ** 2 + theta


@pytest.mark.parametrize("upper, r0, minimum", [
    (4.0, None, 2.5),  # the middle of [0, 4], 2, lies downhill of 2.5
    (2.9, None, 0.5),  # the middle of [0, 2.9], 1.45, lies downhill of 0.5
    (4.0, 0.2, 0.5),
    (4.0, -1.0, 0.5),  # clipped to the bracket's lower end 0, downhill of 0.5
    (4.0, 1.6, 2.5),
])
def test_argmin_finds_the_minimum_downhill_of_its_start(upper, r0, minimum):
    r_star, on_bound = argmin(_two_minima, jnp.asarray(0.0), 0.0, upper, r0=r0)
    assert float(r_star) == pytest.approx(minimum, abs=1e-9) and not bool(on_bound)


def test_argmin_default_tolerance_places_a_non_quadratic_minimum_to_1e_10():
    # E^2 = cosh(r - theta): dE^2/dr = sinh(r - theta) is not linear, the minimum is theta.
    r_star, _ = argmin(lambda r, th: jnp.cosh(r - th), jnp.asarray(1.234), 0.0, 3.0)
    assert abs(float(r_star) - 1.234) <= 1e-10


def test_argmin_r_takes_the_lower_end_s_dtype():
    # A float64 upper end or start (numpy, strongly typed) does not promote a float32 problem.
    r_star, _ = argmin(_two_minima, jnp.float32(0.0), jnp.float32(0.0), np.float64(4.0))
    assert r_star.dtype == jnp.float32
    r_star, _ = argmin(_two_minima, jnp.float32(0.0), jnp.float32(0.0), jnp.float32(4.0),
                       r0=np.float64(1.0))
    assert r_star.dtype == jnp.float32


def test_argmin_max_steps_caps_the_root_find_without_raising():
    # Three gradient evaluations from the middle of [0, 3] are not enough to place cosh's
    # minimum 1.234 to 1e-6: the result is where the cap left it, not an error.
    r_star, _ = argmin(lambda r, th: jnp.cosh(r - th), jnp.asarray(1.234), 0.0, 3.0, max_steps=3)
    assert 1e-6 < abs(float(r_star) - 1.234) < 1.5


def test_argmin_derivative_of_a_shallow_bowl_and_at_zero_curvature():
    # E^2 = (r - theta)^2 / 4: curvature 1/2 (a strict minimum, however shallow), r* = theta,
    # so dr*/dtheta = 1.
    shallow = argmin_derivative(lambda r, th: 0.25 * (r - th) ** 2, jnp.asarray(0.7), jnp.asarray(0.7))
    assert float(shallow) == pytest.approx(1.0, abs=1e-12)
    # E^2 = theta r + r^4 at r = 0: curvature 12 r^2 = 0 with the cross term 1: no strict
    # minimum, NaN (not -1/0).
    flat = argmin_derivative(lambda r, th: th * r + r**4, jnp.asarray(0.0), jnp.asarray(1.0))
    assert np.isnan(float(flat))
    # at a maximum of E^2 (curvature < 0) the implicit function theorem does not apply either
    assert np.isnan(float(argmin_derivative(lambda r, th: -((r - th) ** 2), jnp.asarray(1.0), jnp.asarray(1.0))))
