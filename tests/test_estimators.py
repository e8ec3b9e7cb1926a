"""The estimators E's soft value is (`EstimatorConfig.kind`), against independent values: the
binary-Concrete sample and the relaxed reference draw in their odds forms, the Monte-Carlo
uniforms strictly inside (0, 1), the config's bounds; relaxed-reference tending to E_ref as its
temperature falls, straight-through E_ref's value with relaxed-reference's gradient, Monte-Carlo
estimating E_ref where mean-field is biased; gradients against float64 central differences. The
draws' formulas in `_estimators.py` are what is under test here, so this file reaches them."""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense import metrics
from diffsense.metrics import EstimatorConfig, reference_draw_margins, relaxed_bernoulli
from diffsense.metrics._estimators import mc_uniforms, relaxed_draw, straight_through
from diffsense.runtime import InputError
from diffsense.sensors import Camera, Radar, Suite
from tests import _toy_pipeline as toy
from tests._toy_pipeline import SWERLING, H, radar_objective

_reference = eqx.filter_jit(lambda o, r: o.reference({H: r}))
_e2 = eqx.filter_jit(lambda o, r, tau: o.e2({H: r}, tau))
_value_and_grad = eqx.filter_jit(lambda o, r, tau: jax.value_and_grad(lambda x: o.e2({H: x}, tau))(r))
# r and tau go in as arrays: `eqx.filter_jit` bakes a Python float into the program.
reference = lambda o, r: _reference(o, jnp.asarray(r))
e2 = lambda o, r, tau=1.0: float(_e2(o, jnp.asarray(r), jnp.asarray(tau)))
value_and_grad = lambda o, r, tau=1.0: tuple(map(float, _value_and_grad(o, jnp.asarray(r), jnp.asarray(tau))))
DRAWS = 4


@pytest.fixture(scope="module")
def relaxed():
    return radar_objective(kind="relaxed-reference", draws=DRAWS)


@pytest.fixture(scope="module")
def st():
    return radar_objective(kind="straight-through", draws=DRAWS)


def test_estimator_config_bounds_on_their_edges():
    assert EstimatorConfig(samples=1, reference_draws=2).reference_draws == 2
    with pytest.raises(InputError, match="'exact'"):
        EstimatorConfig(kind="exact")
    with pytest.raises(InputError, match="reference_draws"):
        EstimatorConfig(reference_draws=1)  # a standard error needs two
    with pytest.raises(InputError, match="samples"):
        EstimatorConfig(kind="mc", samples=0)
    for name in ("relax_temperature", "reference_temperature"):
        assert getattr(EstimatorConfig(**{name: 1e-9}), name) == 1e-9
        with pytest.raises(InputError, match=name):
            EstimatorConfig(**{name: 0.0})


@pytest.mark.parametrize("p, u, temperature", [(0.3, 0.8, 0.5), (0.9, 0.05, 2.0), (0.5, 0.5, 0.1)])
def test_relaxed_bernoulli_is_the_binary_concrete_sample(p, u, temperature):
    # Written with odds instead of logits: 1 / (1 + ((1 - p)(1 - u) / (p u))^(1 / lambda)).
    by_hand = 1.0 / (1.0 + ((1.0 - p) * (1.0 - u) / (p * u)) ** (1.0 / temperature))
    assert float(relaxed_bernoulli(jnp.asarray(p), jnp.asarray(u), temperature)) == pytest.approx(by_hand, rel=1e-12)


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


def test_relaxed_draw_against_the_odds_ratio():
    # sigmoid(logit p - logit u) = p (1 - u) / (p (1 - u) + u (1 - p)): an independent form.
    for p, u in [(0.9, 0.1), (0.3, 0.6), (0.7, 0.7), (0.02, 0.5)]:
        odds = p * (1 - u) / (p * (1 - u) + u * (1 - p))
        assert float(relaxed_draw(jnp.asarray(p), jnp.asarray(u), 1.0)) == pytest.approx(odds, rel=1e-12)
    # temperature t: the same form with the odds ratio raised to 1/t
    ratio = (0.6 / 0.4) / (0.5 / 0.5)
    cold = float(relaxed_draw(jnp.asarray(0.6), jnp.asarray(0.5), 0.25))
    assert cold == pytest.approx(ratio**4 / (1 + ratio**4), rel=1e-12)
    # the hard draw 1[u < p] in the limit, and finite values and gradients at 0 and 1
    assert float(relaxed_draw(jnp.asarray(0.51), jnp.asarray(0.5), 1e-6)) == 1.0
    assert float(relaxed_draw(jnp.asarray(0.49), jnp.asarray(0.5), 1e-6)) == 0.0
    for p, u in [(0.0, 0.0), (1.0, 1.0), (0.0, 1.0), (1.0, 0.0)]:
        assert np.isfinite(float(jax.grad(lambda q: relaxed_draw(q, jnp.asarray(u), 0.01))(jnp.asarray(p))))


def test_straight_through_is_hard_in_value_and_relaxed_in_derivative():
    hard, relaxed = jnp.asarray([0.0, 1.0, 1.0]), jnp.asarray([0.3, 0.8, 0.9999])
    assert np.array_equal(np.asarray(straight_through(hard, relaxed)), [0.0, 1.0, 1.0])  # bit for bit
    g = jax.grad(lambda x: jnp.sum(jnp.asarray([1.0, 2.0, 3.0]) * straight_through(hard, x ** 2)))(relaxed)
    np.testing.assert_allclose(np.asarray(g), [0.6, 3.2, 6 * 0.9999], rtol=1e-12)


def test_auto_picks_by_the_law_and_the_number_of_free_parameters(relaxed):
    """Under a declared random law: straight-through (E_ref's value) for one free parameter,
    relaxed-reference for several; mean-field under the threshold law and for a custom sensor,
    which declares no law; explicit relaxed-reference or straight-through under the threshold
    law has nothing to draw and is mean-field too."""
    auto = radar_objective(kind="auto", draws=DRAWS)
    assert auto.estimator_kind == "straight-through"
    assert e2(auto, 10.0) == pytest.approx(float(reference(auto, 10.0).e2), rel=1e-12)
    assert e2(auto, 10.0) != e2(relaxed, 10.0)
    two = dataclasses.replace(auto, names=(H, "range_m"))
    assert two.estimator_kind == "relaxed-reference" and e2(two, 10.0) == e2(relaxed, 10.0)
    threshold, camera = toy.THRESHOLD_RADAR, toy.THRESHOLD_CAMERA
    for sensor, kind in ((threshold, "mean-field"), (toy.ToySensor(), "mean-field"),
                         (Suite((threshold, camera)), "mean-field"),
                         (Suite((SWERLING, camera)), "straight-through"),
                         (Radar.from_toml(), "straight-through"), (Camera.from_toml(), "straight-through")):
        assert eqx.tree_at(lambda o: o.sensor, auto, sensor).estimator_kind == kind
    mean_field = e2(radar_objective(threshold, kind="mean-field", draws=DRAWS), 10.0)
    for kind in ("auto", "relaxed-reference", "straight-through"):
        assert e2(radar_objective(threshold, kind=kind, draws=DRAWS), 10.0) == mean_field


def test_relaxed_reference_tends_to_the_reference_as_the_temperature_falls(relaxed):
    assert np.ptp(np.asarray(reference(relaxed, 8.0).draws)) > 0  # a beam this narrow: random draws
    for r in (8.0, 12.0):
        np.testing.assert_allclose(e2(relaxed, r, 1e-7), float(reference(relaxed, r).e2), rtol=1e-9)
    # warm, the relaxation shows: the gap closes as the temperature falls
    ref = float(reference(relaxed, 8.0).e2)
    gaps = [abs(e2(relaxed, 8.0, tau) - ref) for tau in (50.0, 5.0, 1e-3)]
    assert gaps[0] > gaps[1] > gaps[2] and gaps[0] > 1e-3 * ref


def test_draw_margins_say_when_the_relaxation_is_exact(relaxed):
    # The relaxed draw is within sigmoid(-m_min / lambda) of its hard value: at a temperature far
    # below the smallest margin the estimate is E_ref; far above it, the nearest draw is blurred.
    m = np.asarray(eqx.filter_jit(reference_draw_margins)(relaxed, jnp.asarray(8.0), DRAWS))
    assert m.shape[0] == DRAWS and m.ndim == 4 and np.all(np.isfinite(m)) and np.all(m >= 0)
    ref, lam, m_min = float(reference(relaxed, 8.0).e2), relaxed.estimator.reference_temperature, float(m.min())
    assert m_min > 0
    assert e2(relaxed, 8.0, 1e-3 * m_min / lam) == pytest.approx(ref, rel=1e-9)
    assert abs(e2(relaxed, 8.0, 1e3 * m_min / lam) - ref) > 1e-6 * ref


def test_same_seed_same_value_bit_for_bit(relaxed):
    assert e2(radar_objective(kind="relaxed-reference", draws=DRAWS), 11.0) == e2(relaxed, 11.0)
    assert e2(radar_objective(kind="relaxed-reference", draws=8, key=jax.random.PRNGKey(3)), 8.0) != e2(relaxed, 8.0)


def test_straight_through_has_the_references_value_and_relaxed_references_gradient(st, relaxed):
    assert np.ptp(np.asarray(reference(st, 8.0).draws)) > 0
    for r in (8.0, 12.0, 40.0):
        for tau in (1.0, 30.0):  # the temperature moves the gradient only
            np.testing.assert_allclose(e2(st, r, tau), float(reference(st, r).e2), rtol=1e-12)
    for r in (9.0, 12.0):
        value, grad = value_and_grad(st, r)
        assert abs(grad) > 1e-6
        assert value == pytest.approx(float(reference(st, r).e2), rel=1e-12)
        assert grad == pytest.approx(value_and_grad(relaxed, r)[1], rel=1e-12)
        h = 1e-5  # the relaxed draws bend within 0.01 logit units: a small step
        np.testing.assert_allclose(grad, (e2(relaxed, r + h) - e2(relaxed, r - h)) / (2 * h), rtol=1e-5)
        np.testing.assert_allclose(value_and_grad(relaxed, r)[0], e2(relaxed, r), rtol=1e-12)
    # warm, relaxed-reference's value leaves the reference and straight-through's does not
    ref = float(reference(st, 8.0).e2)
    assert abs(e2(relaxed, 8.0, 50.0) - ref) > 1e-3 * ref and e2(st, 8.0, 50.0) == pytest.approx(ref, rel=1e-12)
    for r in (0.01, 360.0):
        for tau in (1e-3, 1.0):
            assert np.all(np.isfinite(value_and_grad(st, r, tau)))


_forward = eqx.filter_jit(lambda o, r, tau: metrics.value_and_grad(lambda x: o.e2({H: x}, tau))(r))


@pytest.mark.parametrize("kind", ["straight-through", "relaxed-reference"])
def test_forward_mode_equals_reverse_mode(st, relaxed, kind):
    # The solver's one-parameter value-and-gradient carries a tangent through the draws instead.
    o = st if kind == "straight-through" else relaxed
    for r in (9.0, 12.0):
        value, grad = _forward(o, jnp.asarray(r), jnp.asarray(1.0))
        want_value, want_grad = value_and_grad(o, r)
        assert abs(want_grad) > 1e-6
        assert float(value) == pytest.approx(want_value, rel=1e-13) and float(grad) == pytest.approx(want_grad, rel=1e-10)


_two = eqx.filter_jit(lambda o, x: jax.value_and_grad(lambda v: o.e2({H: v[0], "range_m": v[1]}))(x))


@pytest.mark.parametrize("pfa", [1e-12, 0.1])
def test_no_nan_or_inf_at_the_extremes(pfa):
    obj = radar_objective(toy.with_pfa(SWERLING, pfa), kind="relaxed-reference", draws=2)
    for hfov_deg in (0.01, 360.0):
        for range_m in (0.1, 1000.0):
            v, g = _two(obj, jnp.asarray([hfov_deg, range_m]))
            assert np.isfinite(float(v)) and np.all(np.isfinite(np.asarray(g))), (pfa, hfov_deg, range_m)


def test_camera_gradients_and_extremes():
    # The confidence camera through the whole objective with relaxed-reference: against float64
    # central differences at 20 deg (draws on the image's edge) and 40 deg, and finite at HFOV
    # 0.01/360 deg x range 0.1/1000 m.
    camera = radar_objective(Camera.from_toml(toy.LAWS / "camera_confidence.toml"), kind="relaxed-reference", draws=4)
    assert np.ptp(np.asarray(reference(camera, 20.0).draws)) > 0
    for r in (20.0, 40.0):
        h = 1e-5
        up, down = (float(_two(camera, jnp.asarray([r + s, 100.0]))[0]) for s in (h, -h))
        grad = float(_two(camera, jnp.asarray([r, 100.0]))[1][0])
        assert abs(grad) > 1e-3
        np.testing.assert_allclose(grad, (up - down) / (2 * h), rtol=1e-5)
    for hfov_deg in (0.01, 360.0):
        for range_m in (0.1, 1000.0):
            v, g = _two(camera, jnp.asarray([hfov_deg, range_m]))
            assert np.isfinite(float(v)) and np.all(np.isfinite(np.asarray(g))), (hfov_deg, range_m)


def test_monte_carlo_estimates_the_reference_where_mean_field_is_biased():
    # A beam of 8 deg: the target's detections are random events. 64 Monte-Carlo samples, drawn
    # cold (each nearly a hard draw) from their own uniforms, and E_ref's 64 draws estimate the
    # same expectation: within 3 combined standard errors. Mean-field, E^2 of the averaged
    # detections, is biased here by more than 3 of them.
    ref = reference(radar_objective(draws=64), 8.0)
    se = float(np.std(np.asarray(ref.draws), ddof=1)) / 8.0
    mc = e2(radar_objective(kind="mc", samples=64, relax_temperature=1e-4), 8.0)
    mean_field = e2(radar_objective(kind="mean-field"), 8.0)
    assert abs(mc - float(ref.e2)) < 3.0 * math.sqrt(2.0) * se
    assert abs(mean_field - float(ref.e2)) > 3.0 * math.sqrt(2.0) * se


def test_monte_carlo_value_written_out_sample_by_sample():
    # Each sample relaxes the soft detections at the temperature multiplier tau with its own row
    # of fixed uniforms (binary Concrete, in its odds form here); E^2 is the samples' mean.
    lam, tau = 0.3, 0.5
    mc = toy.toy_objective(n=2, instants=4, fill="interp", key=jax.random.PRNGKey(1),
                       estimator=EstimatorConfig(kind="mc", samples=3, relax_temperature=lam))

    @eqx.filter_jit
    def by_hand(obj):
        det = obj.detections({"range_m": 40.0}, "soft", tau)
        p = jnp.clip(det.p_detect, 1e-12, 1.0 - 1e-12)
        total = 0.0
        for k in range(3):
            u = obj.data.mc_uniform[:, k]
            odds = ((1.0 - p) * (1.0 - u) / (p * u)) ** (1.0 / lam)
            total = total + toy.eq12_of(obj, dataclasses.replace(det, p_detect=1.0 / (1.0 + odds)))
        return total / 3

    got = eqx.filter_jit(lambda o: o.e2({"range_m": 40.0}, tau))(mc)
    np.testing.assert_allclose(float(got), float(by_hand(mc)), rtol=1e-9)


@pytest.mark.slow
def test_the_relaxed_draws_are_computed_only_for_a_derivative(st, relaxed):
    # The relaxed draws' value is never read: a value-only program is the reference's K hard
    # passes, and value-and-gradient costs what relaxed-reference's does (XLA's flop counts).
    value = lambda o, r: o.e2({H: r})
    vg = lambda o, r: jax.value_and_grad(lambda x: o.e2({H: x}))(r)
    ref = lambda o, r: o.reference({H: r}).e2
    assert _flops(value, st) <= 1.01 * _flops(ref, st)
    assert _flops(vg, st) <= 1.01 * _flops(vg, relaxed)


def _flops(fn, o) -> float:
    arrays, static = eqx.partition(o, eqx.is_array)
    program = jax.jit(lambda a, r: fn(eqx.combine(a, static), r))
    cost = program.lower(arrays, jnp.asarray(10.0)).compile().cost_analysis()
    return float((cost[0] if isinstance(cost, list) else cost)["flops"])
