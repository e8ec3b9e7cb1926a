"""A suite's reference draws each member's detection on its own (`diffsense.metrics._reference`):
the fused track of a draw is the inverse-variance fusion of the members that drew a detection.

Checked against a numpy recomputation (2x2 inverses, written apart from `fuse`), and by the law of
large numbers against what independent members imply: the track exists with probability
1 - (1 - p_radar)(1 - p_camera), and its mean position given that it exists is the fused
expectation `fuse` forms from the probabilities (`diffsense.sensors._fusion`).
"""

from __future__ import annotations

from dataclasses import replace as dataclasses_replace

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense import config as cfg
from diffsense import sensors as sensor
from diffsense.metrics import EstimatorConfig, make_objective
from diffsense.metrics._reference import detection_events, reference_uniforms
from diffsense.sensors._fusion import Suite
from diffsense.sensors._laws import CameraDetection, RadarDetection
from diffsense.tracks import prediction_frames
from tests._toy_pipeline import TOY_GAIN, ToyPredictor, toy_scenes

RADAR = sensor.Radar(cfg.replace(sensor.load_config("radar"), detection=RadarDetection(law="swerling1")))
CAMERA = sensor.Camera(cfg.replace(sensor.load_config("camera"), detection=CameraDetection(law="confidence")))
NAMES = ("radar.hfov_deg", "camera.hfov_deg")
# Narrow enough that both members see the toy scene's cars on their beam's and image's edges.
R_EDGE = (8.0, 20.0)
Z = 4.0  # the law-of-large-numbers bound in standard errors (Bonferroni over the elements checked)


def suite_objective(kind="relaxed-reference", draws=4, key=None):
    scenes, scenario = toy_scenes(1)
    frames = prediction_frames(scenes.num_frames)[:3]
    return make_objective(scenes, scenario, frames, Suite((RADAR, CAMERA)), ToyPredictor(jnp.asarray(TOY_GAIN)),
                          names=NAMES, key=key, estimator=EstimatorConfig(kind=kind, reference_draws=draws), shard=False)


@pytest.fixture(scope="module")
def suite():
    return suite_objective()


def _r(values):
    return dict(zip(NAMES, (jnp.asarray(v) for v in values)))


@eqx.filter_jit
def _draws(obj, values, draws):
    """Each member's p and uniforms, and the combined detections, of reference draws 0..draws-1."""
    events = detection_events(obj, _r(values))

    def one(d):
        us = events.uniforms(obj.data.noise_key, d)
        det = events.combine([(u < p).astype(p.dtype) for p, u in zip(events.p_detect, us)])
        return us, det

    us, det = jax.lax.map(one, jnp.arange(draws))
    return events.p_detect, us, det


@eqx.filter_jit
def _views(obj, values):
    r = _r(values)
    return obj._per_variant(r, lambda s, p, k, w: obj.sensor.member_views(s, p, k, mode="hard", weather=w))


def _inverse_variance(xs, ys, covs, detected):
    """Fusion of the detecting members at one (frame, vehicle), by numpy's 2x2 inverse."""
    info = [np.linalg.inv(np.array([[c[0], c[1]], [c[1], c[2]]])) for c in covs]
    j = sum(i for i, d in zip(info, detected) if d)
    b = sum(i @ np.array([x, y]) for i, x, y, d in zip(info, xs, ys, detected) if d)
    return np.linalg.solve(j, b)


def test_a_draw_fuses_the_members_that_detect(suite):
    p, us, det = _draws(suite, R_EDGE, 4)
    views = _views(suite, R_EDGE)
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
            xs = [float(view[0].x_m[n, t, v]) for view in views]
            ys = [float(view[0].y_m[n, t, v]) for view in views]
            covs = [(float(c.xx[n, t, v]), float(c.xy[n, t, v]), float(c.yy[n, t, v])) for _, c in views]
            expected = _inverse_variance(xs, ys, covs, who)
            got = np.array([float(det.x_m[k, n, t, v]), float(det.y_m[k, n, t, v])])
            np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-9)
    assert seen[1] >= 10 and seen[2] >= 10, seen  # draws where one member, and both, detect


def test_members_draw_independently_and_the_track_has_the_fused_probability(suite):
    k = 4000
    p, us, det = _draws(suite, R_EDGE, k)
    p = [np.asarray(q) for q in p]
    u = [np.asarray(x) for x in us]
    # each member has its own stream: uncorrelated, and neither is the one-sensor stream
    corr = np.corrcoef(u[0].ravel(), u[1].ravel())[0, 1]
    assert abs(corr) < 3 / np.sqrt(u[0].size)
    own = np.asarray(reference_uniforms(suite.data.noise_key, jnp.asarray(0), p[0].shape[1:], p[0].dtype))
    assert not np.array_equal(own, u[0][0]) and not np.array_equal(own, u[1][0])
    # the track exists with probability 1 - (1 - p_radar)(1 - p_camera)
    fused = 1.0 - (1.0 - p[0]) * (1.0 - p[1])
    share = np.mean(np.asarray(det.p_detect), axis=0)
    edge = (p[0] > 0.05) & (p[0] < 0.95) & (p[1] > 0.05) & (p[1] < 0.95)
    assert edge.sum() >= 20
    se = np.sqrt(fused * (1 - fused) / k)
    # Z standard errors per element: over ~30 elements a family-wise false alarm of ~0.2 %. Drawn
    # from one uniform, the members would give max(p_radar, p_camera): 0.75 -> 0.5 at p = 1/2, 50 SE.
    assert np.all(np.abs(share - fused)[edge] < Z * se[edge] + 1e-12)
    # given that it exists, its mean position is the fused expectation over who detected
    soft = eqx.filter_jit(lambda o, v: o._sensor_detections(_r(v), "hard"))(suite, R_EDGE)  # the members' p, fused
    detected = np.asarray(det.p_detect) > 0
    for coord, expected in (("x_m", soft.x_m), ("y_m", soft.y_m)):
        x = np.asarray(getattr(det, coord))
        count = detected.sum(axis=0)
        mean = np.where(detected, x, 0.0).sum(axis=0) / np.maximum(count, 1)
        var = np.where(detected, (x - mean) ** 2, 0.0).sum(axis=0) / np.maximum(count - 1, 1)
        se_mean = np.sqrt(var / np.maximum(count, 1))
        spread = edge & (se_mean > 1e-6)
        assert spread.sum() >= 10
        np.testing.assert_array_less(np.abs(mean - np.asarray(expected))[spread], Z * se_mean[spread])


def test_same_seed_same_suite_reference_bit_for_bit(suite):
    ref = eqx.filter_jit(lambda o, v: o.reference(_r(v)))
    a, b = ref(suite, R_EDGE), ref(suite_objective(), R_EDGE)
    assert np.ptp(np.asarray(a.draws)) > 0  # the draws differ: both laws are random here
    np.testing.assert_array_equal(np.asarray(a.draws), np.asarray(b.draws))
    other = ref(suite_objective(key=jax.random.PRNGKey(7)), R_EDGE)
    assert not np.array_equal(np.asarray(other.draws), np.asarray(a.draws))


def test_relaxed_reference_of_a_suite_tends_to_its_reference(suite):
    e2 = eqx.filter_jit(lambda o, v, tau: o.e2(_r(v), tau))
    ref = eqx.filter_jit(lambda o, v: o.reference(_r(v)))(suite, R_EDGE)
    cold = float(e2(suite, R_EDGE, jnp.asarray(1e-7)))  # tau as an array: one program for both
    np.testing.assert_allclose(cold, float(ref.e2), rtol=1e-9)
    warm = float(e2(suite, R_EDGE, jnp.asarray(50.0)))
    assert abs(warm - float(ref.e2)) > 1e-3 * float(ref.e2)  # the relaxation shows when warm


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


def test_the_box_solve_judges_answers_on_e_ref_under_a_random_law(suite):
    import diffsense as ds
    from diffsense.study._box_job import _functions
    from diffsense.report._tables import box_table

    laws = {"radar": "configs/sensors/laws/radar_swerling1.toml", "camera": "configs/sensors/laws/camera_confidence.toml"}
    params = {n: (5.0, 60.0) for n in NAMES}
    random = ds.Problem(sensor=["radar", "camera"], params=params, sensor_config=laws)
    ev, fns, _ = _functions(random, suite, None, 10)
    x = list(R_EDGE)
    assert fns.e_hard(x) == ev.e_reference(x) and ev.e_reference(x) != ev.e_hard(x)
    # the threshold law, or the hard estimator: E_hard itself
    threshold = suite_objective()
    threshold = eqx.tree_at(lambda o: o.sensor, threshold, Suite((sensor.Radar.from_toml(), sensor.Camera.from_toml())))
    ev, fns, _ = _functions(ds.Problem(sensor=["radar", "camera"], params=params), threshold, None, 10)
    assert fns.e_hard(x) == ev.e_hard(x)
    ev, fns, _ = _functions(dataclasses_replace(random, estimator="hard"), suite, None, 10)
    assert fns.e_hard(x) == ev.e_hard(x)
    # and the printed summary says so
    result = {"sensor": "radar+camera", "units": {n: "deg" for n in NAMES}, "r_star": dict(zip(NAMES, x)),
              "E_hard_star": 1.0, "E_soft_star": 1.1, "notes": [],
              "reference": {"answer_on": "E_ref", "E_ref_star": 1.2, "E_ref_star_se": 0.01, "draws": 4, "estimator": "auto"},
              "box": {"gradient": dict.fromkeys(NAMES, 0.0), "on_bound": dict.fromkeys(NAMES, ""), "cost_weight": 0.0,
                      "cost": 1.0, "J_star": 1.2, "source": "start 1", "counts": {"soft": 3, "hard": 2}}}
    text = box_table(result)
    assert "2 reference evaluations" in text and "J is judged on E_ref: E_ref(r*) 1.2" in text


def test_draw_margins_of_a_suite_are_the_nearest_member_to_flipping(suite):
    from diffsense.metrics import reference_draw_margins

    m = np.asarray(eqx.filter_jit(reference_draw_margins)(suite, jnp.asarray(R_EDGE), 3))
    p, us, _ = _draws(suite, R_EDGE, 3)

    def logit(x):
        x = np.clip(np.asarray(x, np.float64), 1e-12, 1 - 1e-12)
        return np.log(x) - np.log1p(-x)

    per_member = [np.abs(logit(p[i])[None] - logit(us[i])) for i in range(2)]
    assert m.shape == per_member[0].shape
    edge = (np.asarray(p[0]) > 1e-6) & (np.asarray(p[0]) < 1 - 1e-6) & (np.asarray(p[1]) > 1e-6) & (np.asarray(p[1]) < 1 - 1e-6)
    np.testing.assert_allclose(m[:, edge], np.minimum(*per_member)[:, edge], rtol=1e-6)


def _mc(samples, lam=1e-9):
    obj = suite_objective(kind="mc", draws=samples)
    return dataclasses_replace(obj, estimator=dataclasses_replace(obj.estimator, samples=samples, relax_temperature=lam))


def test_mc_draws_each_member_on_its_own():
    # Cold, an mc sample is a draw of the members' events from the mc stream's uniforms, each
    # member on its own, fused as the reference fuses its draws: written out here draw by draw.
    from diffsense.metrics._coverage import p_tracked
    from diffsense.metrics._reference import MC_STREAM

    mc = _mc(6)

    @eqx.filter_jit
    def by_hand(obj, values, tau):
        events = detection_events(obj, _r(values), "soft", tau)
        total = 0.0
        for k in range(6):
            us = events.uniforms(obj.data.noise_key, jnp.asarray(k), MC_STREAM)
            det = events.combine([(u < p).astype(p.dtype) for p, u in zip(events.p_detect, us)])
            total = total + obj._question(obj._predict(det), p_tracked(obj._target_window(det)))
        return total / 6, us

    # tau as an array: one program for both temperatures (a Python float is baked in)
    expected, us = by_hand(mc, R_EDGE, jnp.asarray(1.0))
    assert len(us) == 2 and not np.allclose(np.asarray(us[0]), np.asarray(us[1]))  # independent members
    e2 = eqx.filter_jit(lambda o, v, tau: o.e2(_r(v), tau))
    got = e2(mc, R_EDGE, jnp.asarray(1.0))
    np.testing.assert_allclose(float(got), float(expected), rtol=1e-9)
    # the temperature multiplier reaches the members' gates (a warm one changes the draws' p)
    warm, _ = by_hand(mc, R_EDGE, jnp.asarray(20.0))
    got = e2(mc, R_EDGE, jnp.asarray(20.0))
    np.testing.assert_allclose(float(got), float(warm), rtol=1e-9)
    assert abs(float(warm) - float(expected)) > 1e-6 * abs(float(expected))


@pytest.mark.slow
def test_mc_of_a_suite_estimates_the_reference():
    # Many cold mc samples and many reference draws estimate the same expectation (their streams
    # are independent): within Z combined standard errors.
    k = 64
    mc = _mc(k)
    ref = eqx.filter_jit(lambda o, v: o.reference(_r(v)))(suite_objective(draws=k), R_EDGE)
    got = float(eqx.filter_jit(lambda o, v: o.e2(_r(v)))(mc, R_EDGE))
    se = float(ref.e2_se) * np.sqrt(2.0)
    assert se > 0 and abs(got - float(ref.e2)) < Z * se, (got, float(ref.e2), se)
