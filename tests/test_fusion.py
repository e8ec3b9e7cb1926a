"""Radar + camera fusion (`diffsense.sensors._fusion.Suite`): detection OR, inverse-variance
positions, qualified parameter names, and the member covariances against sampled noise."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_sensor_scenes import make_scene

from diffsense.runtime._errors import InputError
from diffsense.scene import CAR, TRUCK
from diffsense.sensors import CLEAR, Camera, Radar, Weather
from diffsense.sensors._fusion import Suite, fuse
from diffsense.sensors._member import Covariance, member_view
from tests._toy_pipeline import ToySensor

KEY = jax.random.key(7, impl="rbg")  # threefry compiles ~3 s slower on CPU
RADAR, CAMERA = Radar.from_toml(), Camera.from_toml()
SUITE = Suite((RADAR, CAMERA))


def scene(dtype=np.float64):
    """Ego plus cars ahead at 0-60 deg off the axis, 20-110 m away, one far truck, one padding slot."""
    az = np.radians([3.0, -20.0, 45.0, 1.0, 0.0, 60.0])
    rng = np.array([30.0, 50.0, 25.0, 80.0, 110.0, 15.0])
    x = np.r_[0.0, 4.2 + rng * np.cos(az), 0.0]
    y = np.r_[0.0, rng * np.sin(az), 0.0]
    frames = np.stack([x + 0.5 * t for t in range(4)])
    return make_scene(frames, np.broadcast_to(y, frames.shape), kind=[CAR] * 5 + [TRUCK, CAR, CAR],
                      present=[True] * 7 + [False], dtype=dtype)


# Compiled once per (sensor, mode): eager JAX compiles every primitive on its own, far slower here.
detect = eqx.filter_jit(lambda s, sc, r, k, mode, t: s.detect_with_covariance(sc, r, k, mode=mode, temperature=t))
view = eqx.filter_jit(member_view)
sensor_detect = eqx.filter_jit(lambda s, sc, r, k, mode, t, w=CLEAR: s.detect(sc, r, k, mode=mode, temperature=t,
                                                                                weather=w))


@pytest.mark.parametrize("sensor", [RADAR, CAMERA], ids=["radar", "camera"])
@pytest.mark.parametrize("mode", ["soft", "hard"])
def test_member_view_is_exactly_the_sensors_detections(sensor, mode):
    """In rain and fog (both sensors lose range there), bit for bit."""
    sc = scene()
    r = sensor.defaults() | {"hfov_deg": 90.0}
    weather = Weather(rain_mm_h=40.0, fog_visibility_m=150.0)
    det, _ = view(sensor, sc, r, KEY, mode, 1.5, weather)
    ref = sensor_detect(sensor, sc, r, KEY, mode, 1.5, weather)
    for a, b in zip(jax.tree.leaves(det), jax.tree.leaves(ref)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.parametrize("sensor", [RADAR, CAMERA], ids=["radar", "camera"])
def test_member_covariance_matches_sampled_noise(sensor):
    """4000 noise draws: the sample covariance of each measured position about the truth."""
    sc = scene()
    r = sensor.defaults() | {"hfov_deg": 140.0}
    keys = jax.random.split(jax.random.key(1, impl="rbg"), 4000)
    dets = jax.jit(jax.vmap(lambda k: sensor.detect(sc, r, k, mode="hard")))(keys)
    _, cov = view(sensor, sc, r, KEY, "hard", 1.0)
    ex = np.asarray(dets.x_m[:, 0]) - np.asarray(sc.x_m[0])  # frame 0, [draws, V]
    ey = np.asarray(dets.y_m[:, 0]) - np.asarray(sc.y_m[0])
    for v in range(1, 7):
        sample = np.cov(np.stack([ex[:, v], ey[:, v]]))
        model = np.array([[cov.xx[0, v], cov.xy[0, v]], [cov.xy[0, v], cov.yy[0, v]]])
        scale = np.sqrt(np.diag(model))
        # The standard error of a sample (co)variance from 4000 draws is ~2.2 % of sigma_i sigma_j.
        np.testing.assert_allclose(sample / np.outer(scale, scale), model / np.outer(scale, scale), atol=0.1)


def test_fuse_by_hand():
    """Two members with diagonal covariances (1, 4) and (4, 1) m^2 at (0, 0) and (1, 1) m."""
    one = lambda v: jnp.full((1, 1), v, jnp.float64)  # noqa: E731
    covs = [Covariance(one(1.0), one(0.0), one(4.0)), Covariance(one(4.0), one(0.0), one(1.0))]
    both = [Detections_at(1.0, 0.0, 0.0), Detections_at(1.0, 1.0, 1.0)]
    det, cov = fuse(both, covs)
    # x: weights 1/1 and 1/4 -> 0.25 / 1.25 = 0.2; y: 1/4 and 1 -> 0.8; var_x = 1 / 1.25 = 0.8.
    np.testing.assert_allclose([det.p_detect[0, 0], det.x_m[0, 0], det.y_m[0, 0]], [1.0, 0.2, 0.8], atol=1e-12)
    np.testing.assert_allclose([cov.xx[0, 0], cov.xy[0, 0], cov.yy[0, 0]], [0.8, 0.0, 0.8], atol=1e-12)
    # p = 0.5 each: the track exists with p 0.75; the sets {r}, {c}, {r, c} are equally likely
    # given that, so x = (0 + 1 + 0.2) / 3 = 0.4, y = (0 + 1 + 0.8) / 3 = 0.6.
    det, cov = fuse([Detections_at(0.5, 0.0, 0.0), Detections_at(0.5, 1.0, 1.0)], covs)
    np.testing.assert_allclose([det.p_detect[0, 0], det.x_m[0, 0], det.y_m[0, 0]], [0.75, 0.4, 0.6], atol=1e-12)
    np.testing.assert_allclose(cov.xx[0, 0], (1.0 + 4.0 + 0.8) / 3, atol=1e-12)
    # A blind member (p = 0) contributes nothing.
    det, _ = fuse([Detections_at(0.3, 0.0, 0.0), Detections_at(0.0, 1.0, 1.0)], covs)
    np.testing.assert_allclose([det.p_detect[0, 0], det.x_m[0, 0], det.y_m[0, 0]], [0.3, 0.0, 0.0], atol=1e-12)


def Detections_at(p, x, y):  # noqa: N802 (reads like the class it builds)
    from diffsense.sensors import Detections

    full = lambda v: jnp.full((1, 1), v, jnp.float64)  # noqa: E731
    return Detections(p_detect=full(p), x_m=full(x), y_m=full(y))


@pytest.mark.parametrize("mode", ["soft", "hard"])
def test_blind_camera_leaves_the_radars_tracks(mode):
    sc = scene()
    r = {"radar.hfov_deg": 100.0, "camera.range_m": 1e-3}  # the camera sees nothing beyond 1 mm
    det, _ = detect(SUITE, sc, r, KEY, mode, 1.0)
    radar = sensor_detect(RADAR, sc, {"hfov_deg": 100.0}, jax.random.split(KEY, 2)[0], mode, 1.0)
    p_r = np.asarray(radar.p_detect)
    np.testing.assert_allclose(np.asarray(det.p_detect), p_r, atol=1e-6 if mode == "soft" else 0.0)
    seen = p_r > 1e-3
    assert seen.sum() >= 8
    for a in ("x_m", "y_m"):
        np.testing.assert_allclose(np.asarray(getattr(det, a))[seen], np.asarray(getattr(radar, a))[seen],
                                   rtol=0, atol=1e-5 if mode == "soft" else 1e-9)


def test_soft_p_is_one_minus_the_product_of_misses():
    sc = scene()
    r = {"radar.hfov_deg": 70.0, "camera.hfov_deg": 100.0}
    keys = jax.random.split(KEY, 2)
    det, _ = detect(SUITE, sc, r, KEY, "soft", 2.0)
    views = [view(m, sc, m.defaults() | {"hfov_deg": h}, k, "soft", 2.0)
             for m, h, k in zip((RADAR, CAMERA), (70.0, 100.0), keys)]
    p_r, p_c = (np.asarray(v[0].p_detect) for v in views)
    np.testing.assert_allclose(np.asarray(det.p_detect), 1.0 - (1.0 - p_r) * (1.0 - p_c), rtol=1e-12, atol=1e-15)
    # the ego and the padding slot keep the scene's positions bit for bit (fusion of the
    # members' equal reports would give them back only to rounding)
    for got, want in ((det.x_m, sc.x_m), (det.y_m, sc.y_m)):
        np.testing.assert_array_equal(np.asarray(got)[:, [0, -1]], np.asarray(want)[:, [0, -1]])


def test_fused_covariance_is_below_each_detecting_members():
    """Hard mode: where both detect, the fused covariance is below each member's (PSD order)."""
    sc = scene()
    r = {"radar.hfov_deg": 70.0, "camera.hfov_deg": 100.0}
    keys = jax.random.split(KEY, 2)
    _, cov = detect(SUITE, sc, r, KEY, "hard", 1.0)
    views = [view(m, sc, m.defaults() | {"hfov_deg": h}, k, "hard", 1.0)
             for m, h, k in zip((RADAR, CAMERA), (70.0, 100.0), keys)]
    both = np.argwhere((np.asarray(views[0][0].p_detect) * np.asarray(views[1][0].p_detect)) > 0)
    both = [(t, v) for t, v in both if v != 0]
    assert len(both) >= 4
    m = lambda c, t, v: np.array([[c.xx[t, v], c.xy[t, v]], [c.xy[t, v], c.yy[t, v]]])  # noqa: E731
    for t, v in both:
        for _, c in views:
            assert np.linalg.eigvalsh(m(c, t, v) - m(cov, t, v)).min() >= -1e-12


def test_gradients_match_central_differences_and_jit():
    sc = scene()
    r0 = {"radar.hfov_deg": 70.0, "radar.tx_power_dbm": 12.0, "camera.hfov_deg": 100.0, "camera.width_px": 1500.0}
    w = jnp.linspace(0.5, 1.5, 32).reshape(4, 8)

    def f(r):
        det = SUITE.detect(sc, r, KEY, temperature=2.0)
        return jnp.sum(w * det.p_detect) + 0.01 * jnp.sum(w * det.x_m) + 0.01 * jnp.sum(w[::-1] * det.y_m)

    value = jax.jit(f)
    grad = jax.jit(jax.grad(f))(r0)
    for name, g in grad.items():
        assert np.isfinite(float(g))
        h = 1e-5 * abs(r0[name])
        up, down = dict(r0), dict(r0)
        up[name], down[name] = r0[name] + h, r0[name] - h
        np.testing.assert_allclose(float(g), (float(value(up)) - float(value(down))) / (2 * h), rtol=1e-5, atol=1e-9)


def test_gradients_finite_at_extremes_in_float32():
    """A blind camera and a 359 deg radar: p of 0 and 1 in float32, where log1p(-p) is -inf."""
    sc32 = scene(np.float32)
    extreme = {"radar.hfov_deg": 359.0, "camera.range_m": 1e-3}
    g32 = jax.jit(jax.grad(lambda r: jnp.sum(SUITE.detect(sc32, r, KEY).x_m)))(extreme)
    assert all(np.isfinite(float(v)) for v in g32.values())


def test_suite_detect_passes_temperature_and_weather_to_its_members():
    sc = scene()
    r = {"radar.hfov_deg": 70.0, "camera.hfov_deg": 100.0}
    weather = Weather(rain_mm_h=40.0, fog_visibility_m=150.0)
    fused = eqx.filter_jit(lambda s, sc, r, k, t, w: s.detect_with_covariance(sc, r, k, temperature=t,
                                                                              weather=w)[0])
    want = fused(SUITE, sc, r, KEY, 2.0, weather)
    got = sensor_detect(SUITE, sc, r, KEY, "soft", 2.0, weather)
    for a in ("p_detect", "x_m", "y_m"):
        np.testing.assert_array_equal(np.asarray(getattr(got, a)), np.asarray(getattr(want, a)))
    # the defaults are temperature 1 and clear weather
    plain = eqx.filter_jit(lambda s, sc, r, k: s.detect_with_covariance(sc, r, k)[0])(SUITE, sc, r, KEY)
    np.testing.assert_array_equal(np.asarray(plain.p_detect),
                                  np.asarray(fused(SUITE, sc, r, KEY, 1.0, CLEAR).p_detect))
    # and each matters here: the clear fusion, and the temperature-1 one, differ
    for t, w in ((2.0, CLEAR), (1.0, weather)):
        other = fused(SUITE, sc, r, KEY, t, w).p_detect
        assert np.abs(np.asarray(other) - np.asarray(want.p_detect)).max() > 1e-3


def test_suite_draws_given_as_arrays_are_the_keys_draws():
    # member i draws from split(key, M)[i]; the draws [M, 2, T, V] may be given instead (float32
    # draws too); with three members, three keys
    from diffsense.sensors import measurement_noise

    sc = scene()
    run = eqx.filter_jit(lambda s, sc, k: s.detect(sc, {}, k))
    for suite in (SUITE, Suite((RADAR, CAMERA, RADAR), names=("radar", "camera", "corner"))):
        m = len(suite.members)
        draws = jnp.stack([measurement_noise(k, sc) for k in jax.random.split(KEY, m)])
        by_key, by_draws = run(suite, sc, KEY), run(suite, sc, draws)
        by_draws32 = run(suite, sc, draws.astype(jnp.float32))
        want32 = run(suite, sc, draws.astype(jnp.float32).astype(draws.dtype))
        for a in ("p_detect", "x_m", "y_m"):
            np.testing.assert_allclose(np.asarray(getattr(by_draws, a)), np.asarray(getattr(by_key, a)),
                                       rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(np.asarray(getattr(by_draws32, a)), np.asarray(getattr(want32, a)),
                                       rtol=1e-12, atol=1e-12)


def test_suite_names_specs_and_refusals():
    assert SUITE.kind == "suite" and SUITE.mount_x_m == 4.2
    names = [s.name for s in SUITE.param_specs()]
    # 5 radar and 4 camera parameters of their own, and 3 of mounting each
    assert names[:2] == ["radar.hfov_deg", "radar.vfov_deg"] and "camera.width_px" in names and len(names) == 15
    assert SUITE.spec("camera.width_px").unit == "px"
    with pytest.raises(InputError, match="unknown suite parameter 'hfov_deg'"):
        SUITE.spec("hfov_deg")
    with pytest.raises(InputError, match="named twice: radar"):
        Suite((RADAR, RADAR))
    with pytest.raises(InputError, match="named twice: radar "):  # the name given twice, not the first
        Suite((CAMERA, RADAR, RADAR))
    assert len(Suite((RADAR,) * 6, names=[f"r{i}" for i in range(6)]).members) == 6  # at most 6
    with pytest.raises(InputError, match="a suite has 1 to 6 sensors, got 7"):
        Suite((RADAR,) * 7, names=[f"r{i}" for i in range(7)])
    two = Suite((RADAR, RADAR), names=("front", "corner"))
    assert two.spec("corner.range_m").default == 100.0
    with pytest.raises(InputError, match="cannot be fused"):
        Suite((RADAR, ToySensor())).detect(scene(), {}, KEY)
    with pytest.raises(InputError, match="expected \\(2, 2, 4, 8\\)"):
        SUITE.detect(scene(), {}, jnp.zeros((2, 4, 8)))
