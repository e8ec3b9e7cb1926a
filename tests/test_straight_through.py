"""The straight-through estimator (`diffsense.metrics._estimators`): the value of the reference
E_ref itself, the gradient of relaxed-reference."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense import metrics
from diffsense import sensors as sensor
from diffsense.metrics._estimators import straight_through
from tests.test_reference import H, e2, radar_objective, reference, value_and_grad

DRAWS = 4


@pytest.fixture(scope="module")
def st():
    return radar_objective(kind="straight-through", draws=DRAWS)


def test_straight_through_is_hard_in_value_and_relaxed_in_derivative():
    hard, relaxed = jnp.asarray([0.0, 1.0, 1.0]), jnp.asarray([0.3, 0.8, 0.9999])
    assert np.array_equal(np.asarray(straight_through(hard, relaxed)), [0.0, 1.0, 1.0])  # bit for bit
    g = jax.grad(lambda x: jnp.sum(jnp.asarray([1.0, 2.0, 3.0]) * straight_through(hard, x ** 2)))(relaxed)
    np.testing.assert_allclose(np.asarray(g), [0.6, 3.2, 6 * 0.9999], rtol=1e-12)


def test_value_is_the_reference(st):
    assert np.ptp(np.asarray(reference(st, 8.0).draws)) > 0  # a beam this narrow: random draws
    for r in (8.0, 12.0, 40.0):
        for tau in (1.0, 30.0):  # the temperature moves the gradient only
            np.testing.assert_allclose(float(e2(st, r, tau)), float(reference(st, r).e2), rtol=1e-12)


def test_gradient_is_relaxed_references_and_matches_its_float64_central_differences(st):
    rr = radar_objective(kind="relaxed-reference", draws=DRAWS)
    for r in (9.0, 12.0):
        value, grad = value_and_grad(st, r, 1.0)
        assert abs(float(grad)) > 1e-6
        assert float(value) == pytest.approx(float(reference(st, r).e2), rel=1e-12)
        assert float(grad) == pytest.approx(float(value_and_grad(rr, r, 1.0)[1]), rel=1e-12)
        h = 1e-5  # the relaxed draws bend within 0.01 logit units: a small step
        fd = (float(e2(rr, r + h, 1.0)) - float(e2(rr, r - h, 1.0))) / (2 * h)
        np.testing.assert_allclose(float(grad), fd, rtol=1e-5)
    # warm, relaxed-reference's value leaves the reference and straight-through's does not
    ref = float(reference(st, 8.0).e2)
    assert abs(float(e2(rr, 8.0, 50.0)) - ref) > 1e-3 * ref
    assert float(e2(st, 8.0, 50.0)) == pytest.approx(ref, rel=1e-12)


_forward = eqx.filter_jit(lambda o, r, tau: metrics.value_and_grad(lambda x: o.e2({H: x}, tau))(r))


@pytest.mark.parametrize("kind", ["straight-through", "relaxed-reference"])
def test_forward_mode_equals_reverse_mode(st, kind):
    # The solver's one-parameter value-and-gradient carries a tangent through the draws instead.
    o = st if kind == "straight-through" else radar_objective(kind=kind, draws=DRAWS)
    for r in (9.0, 12.0):
        value, grad = _forward(o, jnp.asarray(r), jnp.asarray(1.0))
        want_value, want_grad = value_and_grad(o, r, 1.0)
        assert abs(float(want_grad)) > 1e-6
        assert float(value) == pytest.approx(float(want_value), rel=1e-13)
        assert float(grad) == pytest.approx(float(want_grad), rel=1e-10)


def test_finite_at_the_extremes(st):
    for r in (0.01, 360.0):
        for tau in (1e-3, 1.0):
            value, grad = value_and_grad(st, jnp.asarray(r), tau)
            assert np.isfinite(float(value)) and np.isfinite(float(grad))


def test_under_the_threshold_law_it_is_mean_field():
    threshold = sensor.Radar.from_toml()
    a = radar_objective(threshold, kind="straight-through", draws=DRAWS)
    m = radar_objective(threshold, kind="mean-field", draws=DRAWS)
    assert float(e2(a, 10.0, 1.0)) == float(e2(m, 10.0, 1.0))


@pytest.mark.slow
def test_the_relaxed_draws_are_computed_only_for_a_derivative(st):
    # The relaxed draws' value is never read: a value-only program is the reference's K hard
    # passes, and value-and-gradient costs what relaxed-reference's does (XLA's flop counts).
    rr = radar_objective(kind="relaxed-reference", draws=DRAWS)
    value = lambda o, r: o.e2({H: r})
    vg = lambda o, r: jax.value_and_grad(lambda x: o.e2({H: x}))(r)
    ref = lambda o, r: o.reference({H: r}).e2
    # (computing the relaxed draws' value too adds a second loop over the draws)
    assert _flops(value, st) <= 1.01 * _flops(ref, st)
    assert _flops(vg, st) <= 1.01 * _flops(vg, rr)


def _flops(fn, o) -> float:
    arrays, static = eqx.partition(o, eqx.is_array)
    program = jax.jit(lambda a, r: fn(eqx.combine(a, static), r))
    cost = program.lower(arrays, jnp.asarray(10.0)).compile().cost_analysis()
    return float((cost[0] if isinstance(cost, list) else cost)["flops"])
