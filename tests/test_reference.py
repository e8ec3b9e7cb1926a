"""The reference objective E_ref (`Objective.reference`, `E(r, mode="reference")`): the hard
objective's expectation over Bernoulli detection draws with common random numbers, for one sensor
and for a suite, whose draw decides each member's detection on its own.

The suite's draws are checked against a numpy recomputation (2x2 inverses, written apart from
the fusion) and, by the law of large numbers, against what independent members imply: the track
exists with probability 1 - (1 - p_radar)(1 - p_camera), and its mean position given that it
exists is the fused expectation the suite forms from the probabilities. `_reference.py`'s draws
and their summary are what is under test here, so this file reaches them.
"""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffsense.metrics._reference as _reference
from diffsense import metrics
from diffsense.metrics import EstimatorConfig, make_objective
from diffsense.sensors import Camera, Radar, Suite, Weather
from diffsense.tracks import prediction_frames
from tests import _toy_pipeline as toy
from tests._toy_pipeline import SWERLING, H, radar_objective

__all__ = ["SWERLING", "radar_objective"]  # the study's tests build on them

_ref = eqx.filter_jit(lambda o, r: o.reference({H: r}))
_hard = eqx.filter_jit(lambda o, r: o({H: r}, mode="hard"))
reference = lambda o, r: _ref(o, jnp.asarray(r))
hard = lambda o, r: _hard(o, jnp.asarray(r))


@pytest.fixture(scope="module")
def swerling():
    return radar_objective()


def test_summary_of_the_draws_by_hand():
    # draws 1 and 3: mean 2, sample sd sqrt(2), so se sqrt(2) / sqrt(2) = 1; E = sqrt(2) and by
    # the delta method its se is 1 / (2 sqrt(2)).
    s = _reference.summarise(jnp.array([1.0, 3.0]))
    assert float(s.e2) == 2.0 and float(s.e2_se) == pytest.approx(1.0, rel=1e-12)
    assert float(s.e) == pytest.approx(math.sqrt(2.0), rel=1e-12)
    assert float(s.e_se) == pytest.approx(1.0 / (2.0 * math.sqrt(2.0)), rel=1e-12)
    s = _reference.summarise(jnp.array([0.25, 0.25]))  # E^2 under 1 m^2 is still positive: E = 0.5
    assert float(s.e) == pytest.approx(0.5, rel=1e-12) and float(s.e_se) == 0.0
    one = _reference.summarise(jnp.array([4.0]))  # one draw: no spread to estimate, se 0
    assert (float(one.e), float(one.e2_se), float(one.e_se)) == (2.0, 0.0, 0.0)
    zero = _reference.summarise(jnp.zeros(3))  # a zero objective: zero, with finite gradients
    assert (float(zero.e), float(zero.e_se)) == (0.0, 0.0)
    e_and_se = lambda d: _reference.summarise(d).e + _reference.summarise(d).e_se  # noqa: E731
    assert bool(jnp.all(jnp.isfinite(jax.grad(e_and_se)(jnp.zeros(3)))))


def test_deterministic_law_reference_is_the_hard_objective():
    obj = radar_objective(toy.THRESHOLD_RADAR)
    ref = reference(obj, 12.0)
    assert ref.draws.shape == (1,) and float(ref.e_se) == 0.0
    assert float(ref.e) == float(hard(obj, 12.0))
    called = eqx.filter_jit(lambda o, r: o({H: r}, mode="reference"))(obj, 12.0)
    assert float(called) == pytest.approx(float(ref.e), rel=1e-12)


def test_which_sensors_are_drawn():
    """The physical profile's radar and camera detect by probabilistic laws and are drawn; the
    paper profile's, and the threshold law's, are deterministic (and a suite of them), a suite
    with one random member is random, and a custom sensor declares no law and is drawn."""
    radar, camera = toy.THRESHOLD_RADAR, toy.THRESHOLD_CAMERA
    paper = (Radar.from_toml(None, "paper"), Camera.from_toml(None, "paper"))
    assert all(metrics.is_deterministic(s) for s in (radar, camera, Suite((radar, camera)), *paper))
    shipped = (Radar.from_toml(), Camera.from_toml())
    assert not any(metrics.is_deterministic(s) for s in (*shipped, SWERLING, Suite((SWERLING, camera)), toy.ToySensor()))


def test_same_seed_same_reference_bit_for_bit(swerling):
    a, b = reference(swerling, 12.0), reference(radar_objective(), 12.0)
    np.testing.assert_array_equal(np.asarray(a.draws), np.asarray(b.draws))
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


def test_draws_are_bernoulli_of_the_sensor_probability_and_hard_is_their_median(swerling):
    scene = jax.tree.map(lambda a: a[0], swerling.data.scenes)
    p = np.asarray(swerling.sensor.detect(scene, {H: 12.0}, swerling.data.noise_key[0], mode="hard").p_detect)[None]
    k = 4000
    u = jax.vmap(lambda d: _reference.reference_uniforms(swerling.data.noise_key, d, p.shape[1:], p.dtype))(jnp.arange(k))
    share = np.mean(np.asarray(u) < p[None], axis=0)
    edge = (p > 0.05) & (p < 0.95)
    assert edge.sum() >= 5  # there are (frame, vehicle) pairs on the beam's edge
    assert np.all(np.abs(share - p)[edge] < 3 * np.sqrt(p * (1 - p) / k)[edge] + 1e-12)
    median = np.asarray(swerling.detections({H: 12.0}, "hard").p_detect)
    np.testing.assert_array_equal(median, (p >= 0.5).astype(p.dtype))


def test_soft_gradient_matches_float64_central_differences(swerling):
    vg = eqx.filter_jit(lambda o, r: jax.value_and_grad(lambda x: o.e2({H: x}))(r))
    for r in (9.0, 16.0):
        _, grad = vg(swerling, jnp.asarray(r))
        h = 1e-4
        fd = (float(vg(swerling, jnp.asarray(r + h))[0]) - float(vg(swerling, jnp.asarray(r - h))[0])) / (2 * h)
        assert abs(float(grad)) > 1e-6
        np.testing.assert_allclose(float(grad), fd, rtol=1e-5)


def test_other_draw_indices_are_independent_draws_of_the_same_scene(swerling):
    # E_ref's own draws are indices 0 ... K-1; indices from K on are fresh draws of the same scene,
    # so a block of 2K draws is the mean of the two K-blocks, and the default is the first block.
    on = eqx.filter_jit(lambda o, r, ids: o.reference({H: r}, draws=ids))
    own, fresh, both = (on(swerling, jnp.asarray(8.0), jnp.arange(a, b)) for a, b in ((0, 4), (4, 8), (0, 8)))
    np.testing.assert_array_equal(np.asarray(own.draws), np.asarray(reference(swerling, 8.0).draws))
    np.testing.assert_array_equal(np.asarray(both.draws), np.concatenate([np.asarray(own.draws), np.asarray(fresh.draws)]))
    assert not np.array_equal(np.asarray(fresh.draws), np.asarray(own.draws))
    assert float(both.e2) == pytest.approx(0.5 * (float(own.e2) + float(fresh.e2)), rel=1e-12)


def test_uniforms_keep_members_and_streams_apart_in_the_given_dtype():
    keys = jax.random.split(jax.random.PRNGKey(0), 2)
    p = jnp.full((2, 5, 3), 0.5, jnp.float32)
    events = _reference.DetectionEvents(p_detect=[p, p], members=(0, 1), combine=lambda drawn: drawn)
    ref, mc = events.uniforms(keys, jnp.asarray(0)), events.uniforms(keys, jnp.asarray(0), _reference.MC_STREAM)
    assert all(u.dtype == jnp.float32 and u.shape == (2, 5, 3) for u in ref + mc)
    assert not np.allclose(ref[0], ref[1]) and not np.allclose(mc[0], mc[1])  # members independent
    assert not np.allclose(ref[0], mc[0]) and not np.allclose(ref[1], mc[1])  # mc's own stream
    member_1 = _reference.reference_uniforms(keys, jnp.asarray(0), (5, 3), jnp.float32, 1, _reference.MC_STREAM)
    np.testing.assert_array_equal(mc[1], member_1)
    assert _reference.reference_uniforms(keys, jnp.asarray(0), (5, 3), jnp.float32).dtype == jnp.float32


def test_detection_events_are_the_sensors_own_probabilities_at_the_temperature():
    obj = toy.toy_objective(n=1, instants=2)
    r = {"range_m": jnp.asarray(40.0)}
    soft = eqx.filter_jit(lambda o: (_reference.detection_events(o, r, "soft", 0.5).p_detect[0],
                                     o.detections(r, "soft", 0.5).p_detect))(obj)
    np.testing.assert_array_equal(*soft)
    assert float(jnp.min(jnp.abs(soft[0] - 0.5))) < 0.5  # some p strictly between 0 and 1


# -- a suite ----------------------------------------------------------------------------------
CAMERA = Camera.from_toml(toy.LAWS / "camera_confidence.toml")
NAMES = ("radar.hfov_deg", "camera.hfov_deg")
R_EDGE = (8.0, 20.0)  # narrow enough that both members see the toy cars on their beam's and image's edges
Z = 4.0  # the law-of-large-numbers bound in standard errors (Bonferroni over the elements checked)


def suite_objective(kind="relaxed-reference", draws=4, key=None, **kwargs):
    scenes, scenario = toy.toy_scenes(1)
    return make_objective(scenes, scenario, prediction_frames(scenes.num_frames)[:3], Suite((SWERLING, CAMERA)),
                          toy.ToyPredictor(jnp.asarray(toy.TOY_GAIN)), names=NAMES, key=key, shard=False,
                          estimator=EstimatorConfig(kind=kind, reference_draws=draws), **kwargs)


@pytest.fixture(scope="module")
def suite():
    return suite_objective()


def _r(values):
    return dict(zip(NAMES, (jnp.asarray(v) for v in values)))


@eqx.filter_jit
def _draws(obj, values, draws):
    """Each member's p and uniforms, and the combined detections, of reference draws 0..draws-1."""
    events = _reference.detection_events(obj, _r(values))

    def one(d):
        us = events.uniforms(obj.data.noise_key, d)
        return us, events.combine([(u < p).astype(p.dtype) for p, u in zip(events.p_detect, us)])

    us, det = jax.lax.map(one, jnp.arange(draws))
    return events.p_detect, us, det


def _per_variant(obj, values, look):
    """look(sensor, scene, r, key, weather) of every variant (the suite's public methods)."""
    r = _r(values)
    return jax.vmap(lambda s, k, w: look(obj.sensor, s, r, k, w))(obj.data.scenes, obj.data.noise_key, obj.weather)


_on_variants = eqx.filter_jit(_per_variant)


def _inverse_variance(xs, ys, covs, detected):
    """Fusion of the detecting members at one (frame, vehicle), by numpy's 2x2 inverse."""
    info = [np.linalg.inv(np.array([[c[0], c[1]], [c[1], c[2]]])) for c in covs]
    j = sum(i for i, d in zip(info, detected) if d)
    b = sum(i @ np.array([x, y]) for i, x, y, d in zip(info, xs, ys, detected) if d)
    return np.linalg.solve(j, b)


def test_a_draw_fuses_the_members_that_detect(suite):
    p, us, det = _draws(suite, R_EDGE, 4)
    views = _on_variants(suite, R_EDGE, lambda m, s, r, k, w: m.member_views(s, r, k, mode="hard", weather=w))
    present = np.asarray(suite.data.scenes.present) != 0
    seen = {1: 0, 2: 0}
    for k in range(4):
        drawn = [np.asarray(us[i][k]) < np.asarray(p[i]) for i in range(2)]
        np.testing.assert_array_equal(np.asarray(det.p_detect[k]), (drawn[0] | drawn[1]).astype(float))
        for n, t, v in zip(*np.nonzero(drawn[0] | drawn[1])):
            if v == 0 or not present[n, v]:
                continue  # the ego and padding keep the scene's positions
            who = [bool(d[n, t, v]) for d in drawn]
            seen[sum(who)] += 1
            xs, ys = ([float(getattr(view[0], c)[n, t, v]) for view in views] for c in ("x_m", "y_m"))
            covs = [(float(c.xx[n, t, v]), float(c.xy[n, t, v]), float(c.yy[n, t, v])) for _, c in views]
            got = np.array([float(det.x_m[k, n, t, v]), float(det.y_m[k, n, t, v])])
            np.testing.assert_allclose(got, _inverse_variance(xs, ys, covs, who), rtol=1e-9, atol=1e-9)
    assert seen[1] >= 10 and seen[2] >= 10, seen  # draws where one member, and both, detect


def test_members_draw_independently_and_the_track_has_the_fused_probability(suite):
    k = 4000
    p, us, det = _draws(suite, R_EDGE, k)
    p, u = [np.asarray(q) for q in p], [np.asarray(x) for x in us]
    # each member has its own stream: uncorrelated, and neither is the one-sensor stream
    assert abs(np.corrcoef(u[0].ravel(), u[1].ravel())[0, 1]) < 3 / np.sqrt(u[0].size)
    own = np.asarray(_reference.reference_uniforms(suite.data.noise_key, jnp.asarray(0), p[0].shape[1:], p[0].dtype))
    assert not np.array_equal(own, u[0][0]) and not np.array_equal(own, u[1][0])
    # the track exists with probability 1 - (1 - p_radar)(1 - p_camera)
    fused = 1.0 - (1.0 - p[0]) * (1.0 - p[1])
    share = np.mean(np.asarray(det.p_detect), axis=0)
    edge = (p[0] > 0.05) & (p[0] < 0.95) & (p[1] > 0.05) & (p[1] < 0.95)
    assert edge.sum() >= 20
    # Z standard errors per element: over ~30 elements a family-wise false alarm of ~0.2 %. Drawn
    # from one uniform, the members would give max(p_radar, p_camera): 0.75 -> 0.5 at p = 1/2, 50 SE.
    assert np.all(np.abs(share - fused)[edge] < Z * np.sqrt(fused * (1 - fused) / k)[edge] + 1e-12)
    # given that it exists, its mean position is the fused expectation over who detected
    expected = _on_variants(suite, R_EDGE, lambda m, s, r, key, w: m.detect(s, r, key, mode="hard", weather=w))
    detected = np.asarray(det.p_detect) > 0
    for coord in ("x_m", "y_m"):
        x = np.asarray(getattr(det, coord))
        count = detected.sum(axis=0)
        mean = np.where(detected, x, 0.0).sum(axis=0) / np.maximum(count, 1)
        var = np.where(detected, (x - mean) ** 2, 0.0).sum(axis=0) / np.maximum(count - 1, 1)
        se_mean = np.sqrt(var / np.maximum(count, 1))
        spread = edge & (se_mean > 1e-6)
        assert spread.sum() >= 10
        np.testing.assert_array_less(np.abs(mean - np.asarray(getattr(expected, coord)))[spread], Z * se_mean[spread])


@pytest.mark.parametrize("mode", ["soft", "hard"])
def test_a_suites_events_are_its_members_views_in_the_objectives_weather(mode):
    # at r, the mode, the temperature multiplier and the variants' rain (so a dropped argument shows)
    obj = suite_objective(weather=Weather(rain_mm_h=50.0))
    values = (8.0, 20.0)

    @eqx.filter_jit  # one program, so that equal means equal
    def both(o):
        look = lambda m, s, r, k, w: m.member_views(s, r, k, mode=mode, temperature=0.5, weather=w)  # noqa: E731
        return _reference.detection_events(o, _r(values), mode, 0.5).p_detect, _per_variant(o, values, look)

    events, views = both(obj)
    for got, (want, _) in zip(events, views, strict=True):
        np.testing.assert_array_equal(np.asarray(got), np.asarray(want.p_detect))


def test_same_seed_same_suite_reference_bit_for_bit(suite):
    ref = eqx.filter_jit(lambda o, v: o.reference(_r(v)))
    a, b = ref(suite, R_EDGE), ref(suite_objective(), R_EDGE)
    assert np.ptp(np.asarray(a.draws)) > 0  # the draws differ: both laws are random here
    np.testing.assert_array_equal(np.asarray(a.draws), np.asarray(b.draws))
    assert not np.array_equal(np.asarray(ref(suite_objective(key=jax.random.PRNGKey(7)), R_EDGE).draws),
                              np.asarray(a.draws))


def test_relaxed_reference_of_a_suite_tends_to_its_reference(suite):
    e2 = eqx.filter_jit(lambda o, v, tau: o.e2(_r(v), tau))
    ref = float(eqx.filter_jit(lambda o, v: o.reference(_r(v)))(suite, R_EDGE).e2)
    np.testing.assert_allclose(float(e2(suite, R_EDGE, jnp.asarray(1e-7))), ref, rtol=1e-9)
    assert abs(float(e2(suite, R_EDGE, jnp.asarray(50.0))) - ref) > 1e-3 * ref  # the relaxation shows warm


def test_suite_gradient_against_float64_central_differences_and_finite_at_extremes(suite):
    vg = eqx.filter_jit(lambda o, x: jax.value_and_grad(lambda v: o.e2(dict(zip(NAMES, v))))(x))
    x = jnp.asarray(R_EDGE)
    _, g = vg(suite, x)
    h = 1e-5
    for i in range(2):
        step = jnp.zeros(2).at[i].set(h)
        fd = (float(vg(suite, x + step)[0]) - float(vg(suite, x - step)[0])) / (2 * h)
        assert abs(float(g[i])) > 1e-6
        np.testing.assert_allclose(float(g[i]), fd, rtol=1e-5)
    for a in (0.01, 360.0):
        for b in (0.01, 360.0):
            v, g = vg(suite, jnp.asarray([a, b]))
            assert np.isfinite(float(v)) and np.all(np.isfinite(np.asarray(g))), (a, b)


def test_draw_margins_of_a_suite_are_the_nearest_member_to_flipping(suite):
    m = np.asarray(eqx.filter_jit(metrics.reference_draw_margins)(suite, jnp.asarray(R_EDGE), 3))
    p, us, _ = _draws(suite, R_EDGE, 3)

    def logit(x):
        x = np.clip(np.asarray(x, np.float64), 1e-12, 1 - 1e-12)
        return np.log(x) - np.log1p(-x)

    per_member = [np.abs(logit(p[i])[None] - logit(us[i])) for i in range(2)]
    assert m.shape == per_member[0].shape
    edge = np.all([(np.asarray(q) > 1e-6) & (np.asarray(q) < 1 - 1e-6) for q in p], axis=0)
    np.testing.assert_allclose(m[:, edge], np.minimum(*per_member)[:, edge], rtol=1e-6)


def _mc(samples, lam=1e-9):
    obj = suite_objective(kind="mc", draws=samples)
    return dataclasses.replace(obj, estimator=dataclasses.replace(obj.estimator, samples=samples, relax_temperature=lam))


def test_mc_draws_each_member_on_its_own():
    # Cold, an mc sample is a draw of the members' events from the mc stream's uniforms, each
    # member on its own, fused as the reference fuses its draws: written out here draw by draw.
    mc = _mc(6)

    @eqx.filter_jit
    def by_hand(obj, values, tau):
        events = _reference.detection_events(obj, _r(values), "soft", tau)
        total = 0.0
        for k in range(6):
            us = events.uniforms(obj.data.noise_key, jnp.asarray(k), _reference.MC_STREAM)
            total = total + toy.eq12_of(obj, events.combine([(u < p).astype(p.dtype) for p, u in zip(events.p_detect, us)]))
        return total / 6, us

    e2 = eqx.filter_jit(lambda o, v, tau: o.e2(_r(v), tau))
    expected, us = by_hand(mc, R_EDGE, jnp.asarray(1.0))  # tau as an array: one program for both
    assert len(us) == 2 and not np.allclose(np.asarray(us[0]), np.asarray(us[1]))  # independent members
    np.testing.assert_allclose(float(e2(mc, R_EDGE, jnp.asarray(1.0))), float(expected), rtol=1e-9)
    # the temperature multiplier reaches the members' gates (a warm one changes the draws' p)
    warm, _ = by_hand(mc, R_EDGE, jnp.asarray(20.0))
    np.testing.assert_allclose(float(e2(mc, R_EDGE, jnp.asarray(20.0))), float(warm), rtol=1e-9)
    assert abs(float(warm) - float(expected)) > 1e-6 * abs(float(expected))


@pytest.mark.slow
def test_mc_of_a_suite_estimates_the_reference():
    # Many cold mc samples and many reference draws estimate the same expectation (their streams
    # are independent): within Z combined standard errors.
    k = 64
    ref = eqx.filter_jit(lambda o, v: o.reference(_r(v)))(suite_objective(draws=k), R_EDGE)
    got = float(eqx.filter_jit(lambda o, v: o.e2(_r(v)))(_mc(k), R_EDGE))
    se = float(ref.e2_se) * np.sqrt(2.0)
    assert se > 0 and abs(got - float(ref.e2)) < Z * se, (got, float(ref.e2), se)
