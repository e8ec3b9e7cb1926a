"""Sensor suites: detection as the OR of independent members (p = 1 - prod(1 - p_i)), positions
by inverse-(co)variance weighting, each member's line-of-sight covariance against hand values and
sampled noise, qualified parameter names, custom members, and the refusals that guard them."""

from __future__ import annotations

import math
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _sensor_scenes import make_scene

from diffsense import sensors
from diffsense.runtime import InputError
from diffsense.scene import CAR, TRUCK
from diffsense.sensors import (
    CLEAR,
    Camera,
    Covariance,
    Detections,
    Radar,
    Suite,
    Weather,
)
from tests._toy_pipeline import ToySensor

KEY = jax.random.key(7, impl="rbg")  # threefry compiles ~3 s slower on CPU
RADAR, CAMERA = Radar.from_toml(), Camera.from_toml()
SUITE = Suite((RADAR, CAMERA))
FLOOR = sensors.VARIANCE_FLOOR_M2  # 1 mm^2 added to every variance
LAWS = Path(__file__).resolve().parents[1] / "configs" / "sensors" / "laws"


def scene(dtype=np.float64):
    """Ego plus cars ahead at 0-60 deg off the axis, 20-110 m away, one far truck, one padding slot."""
    az = np.radians([3.0, -20.0, 45.0, 1.0, 0.0, 60.0])
    rng = np.array([30.0, 50.0, 25.0, 80.0, 110.0, 15.0])
    x = np.r_[0.0, 4.2 + rng * np.cos(az), 0.0]
    y = np.r_[0.0, rng * np.sin(az), 0.0]
    frames = np.stack([x + 0.5 * t for t in range(4)])
    return make_scene(frames, np.broadcast_to(y, frames.shape), kind=[CAR] * 5 + [TRUCK, CAR, CAR],
                      present=[True] * 7 + [False], dtype=dtype)


class ToyWithCovariance(ToySensor):
    """The toy sensor with a fixed measurement covariance: 4 m^2 in x, 9 m^2 in y, 1 m^2 across."""

    def measurement_covariance(self, scene, r, mode, temperature, weather) -> Covariance:
        ones = np.ones(scene.x_m.shape)
        return Covariance(xx=4.0 * ones, xy=1.0 * ones, yy=9.0 * ones)


# Compiled once per (sensor, mode): eager JAX compiles every primitive on its own, far slower here.
detect = eqx.filter_jit(lambda s, sc, r, k, mode, t, w=CLEAR: s.detect_with_covariance(sc, r, k, mode=mode,
                                                                                        temperature=t, weather=w))
views = eqx.filter_jit(lambda s, sc, r, k, mode, t, w=CLEAR: s.member_views(sc, r, k, mode=mode, temperature=t,
                                                                            weather=w))
sensor_detect = eqx.filter_jit(lambda s, sc, r, k, mode, t, w=CLEAR: s.detect(sc, r, k, mode=mode, temperature=t,
                                                                                weather=w))


def alone(sensor):
    return Suite((sensor,), names=("m",))


@pytest.mark.parametrize("sensor", [RADAR, CAMERA], ids=["radar", "camera"])
@pytest.mark.parametrize("mode", ["soft", "hard"])
def test_a_members_view_is_exactly_the_sensors_detections(sensor, mode):
    """In rain and fog (both sensors lose range there), bit for bit."""
    weather = Weather(rain_mm_h=40.0, fog_visibility_m=150.0)
    (det, _), = views(alone(sensor), scene(), {"m.hfov_deg": 90.0}, KEY, mode, 1.5, weather)
    ref = sensor_detect(sensor, scene(), {"hfov_deg": 90.0}, jax.random.split(KEY, 1)[0], mode, 1.5, weather)
    for a, b in zip(jax.tree.leaves(det), jax.tree.leaves(ref), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.parametrize("left_m", [0.0, 3.0])
def test_the_line_of_sight_covariance_by_hand(left_m):
    # The camera at 30 deg: sigma_Z = R^2 0.5 / (k 0.12) along the line of sight and a bearing sigma of
    # 0.5 / k across it (k = 1280 px / 30 deg), so the variances are sigma_Z^2 + 1e-6 along and
    # (R^2 + sigma_Z^2) sigma_b^2 + 1e-6 across. Vehicle 1 sits at the sensor (no line of sight:
    # straight ahead is taken), 2 is 2 m ahead of it, 3 10 m to its left, 4 0.5 m to its left. The
    # covariance moves with the road: the same for any left_m.
    k = 1280 / math.radians(30.0)
    sx = CAMERA.mount_x_m
    sc = make_scene([[0.0, sx, sx + 2.0, sx, sx]], np.array([[0.0, 0.0, 0.0, 10.0, 0.5]]) + left_m,
                    length_m=[4.5, 0.2, 0.2, 0.2, 0.2], width_m=[1.8, 0.2, 0.2, 0.2, 0.2])
    (_, cov), = views(alone(CAMERA), sc, {}, KEY, "hard", 1.0)
    ranges = np.array([0.0, 2.0, 10.0, 0.5])
    depth = ranges**2 * 0.5 / (k * 0.12)
    along, across = depth**2 + FLOOR, (ranges**2 + depth**2) * (0.5 / k) ** 2 + FLOOR
    sideways = np.array([False, False, True, True])
    np.testing.assert_allclose(np.asarray(cov.xx)[0, 1:], np.where(sideways, across, along), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(cov.yy)[0, 1:], np.where(sideways, along, across), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(cov.xy)[0, 1:], 0.0, atol=1e-15)


@pytest.mark.parametrize("sensor", [RADAR, CAMERA], ids=["radar", "camera"])
def test_a_members_covariance_matches_its_sampled_noise(sensor):
    """4000 noise draws: the sample covariance of each measured position about the truth."""
    sc, r = scene(), sensor.defaults() | {"hfov_deg": 140.0}
    keys = jax.random.split(jax.random.key(1, impl="rbg"), 4000)
    dets = jax.jit(jax.vmap(lambda k: sensor.detect(sc, r, k, mode="hard")))(keys)
    (_, cov), = views(alone(sensor), sc, {"m.hfov_deg": 140.0}, KEY, "hard", 1.0)
    ex = np.asarray(dets.x_m[:, 0]) - np.asarray(sc.x_m[0])  # frame 0, [draws, V]
    ey = np.asarray(dets.y_m[:, 0]) - np.asarray(sc.y_m[0])
    for v in range(1, 7):
        sample = np.cov(np.stack([ex[:, v], ey[:, v]]))
        model = np.array([[cov.xx[0, v], cov.xy[0, v]], [cov.xy[0, v], cov.yy[0, v]]])
        scale = np.outer(*(2 * [np.sqrt(np.diag(model))]))
        # The standard error of a sample (co)variance from 4000 draws is ~2.2 % of sigma_i sigma_j.
        np.testing.assert_allclose(sample / scale, model / scale, atol=0.1)


def _fuse(p, x, y, covs, drawn=None):
    """fuse_members on a one-frame scene of the ego and one car (index 1) with the members' values
    (and `drawn` 0/1 detections in place of their p)."""
    sc = make_scene([[0.0, 10.0]], [[0.0, 0.0]])
    full = lambda v: jnp.asarray([[0.0, v]])  # noqa: E731
    cov = lambda xx, yy: Covariance(full(xx), full(0.0), full(yy))  # noqa: E731
    member = [(Detections(full(pi), full(xi), full(yi)), cov(*c)) for pi, xi, yi, c in zip(p, x, y, covs)]
    det, fused = sensors.fuse_members(sc, member, None if drawn is None else [full(v) for v in drawn])
    return [float(det.p_detect[0, 1]), float(det.x_m[0, 1]), float(det.y_m[0, 1])], fused


def test_fusion_by_hand():
    """Two members with diagonal covariances (1, 4) and (4, 1) m^2 at (0, 0) and (1, 1) m."""
    covs = [(1.0, 4.0), (4.0, 1.0)]
    # x: weights 1/1 and 1/4 -> 0.25 / 1.25 = 0.2; y: 1/4 and 1 -> 0.8; var_x = 1 / 1.25 = 0.8.
    got, cov = _fuse([1.0, 1.0], [0.0, 1.0], [0.0, 1.0], covs)
    np.testing.assert_allclose(got, [1.0, 0.2, 0.8], atol=1e-12)
    np.testing.assert_allclose([cov.xx[0, 1], cov.xy[0, 1], cov.yy[0, 1]], [0.8, 0.0, 0.8], atol=1e-12)
    # p = 0.5 each: the track exists with p 0.75; the sets {r}, {c}, {r, c} are equally likely
    # given that, so x = (0 + 1 + 0.2) / 3 = 0.4, y = (0 + 1 + 0.8) / 3 = 0.6.
    got, cov = _fuse([0.5, 0.5], [0.0, 1.0], [0.0, 1.0], covs)
    np.testing.assert_allclose(got, [0.75, 0.4, 0.6], atol=1e-12)
    np.testing.assert_allclose(cov.xx[0, 1], (1.0 + 4.0 + 0.8) / 3, atol=1e-12)
    got, _ = _fuse([0.3, 0.0], [0.0, 1.0], [0.0, 1.0], covs)  # a blind member contributes nothing
    np.testing.assert_allclose(got, [0.3, 0.0, 0.0], atol=1e-12)
    # a draw decides each member: only the second detected, so the track is its measurement
    got, cov = _fuse([0.5, 0.5], [0.0, 1.0], [0.0, 1.0], covs, drawn=[0.0, 1.0])
    np.testing.assert_allclose(got + [float(cov.xx[0, 1]), float(cov.yy[0, 1])], [1.0, 1.0, 1.0, 4.0, 1.0], atol=1e-12)


def test_soft_p_is_one_minus_the_product_of_misses_and_the_ego_and_padding_keep_their_place():
    sc, r = scene(), {"radar.hfov_deg": 70.0, "camera.hfov_deg": 100.0}
    det, _ = detect(SUITE, sc, r, KEY, "soft", 2.0)
    p_r, p_c = (np.asarray(v[0].p_detect) for v in views(SUITE, sc, r, KEY, "soft", 2.0))
    np.testing.assert_allclose(np.asarray(det.p_detect), 1.0 - (1.0 - p_r) * (1.0 - p_c), rtol=1e-12, atol=1e-15)
    for got, want in ((det.x_m, sc.x_m), (det.y_m, sc.y_m)):  # bit for bit, not fused to rounding
        np.testing.assert_array_equal(np.asarray(got)[:, [0, -1]], np.asarray(want)[:, [0, -1]])


def test_the_fused_covariance_is_below_each_detecting_members():
    # Under the threshold law, whose hard detections are 0 or 1 (whichever law the profile defaults to).
    suite = Suite(tuple(type(s).from_toml(LAWS / f"{s.kind}_threshold.toml") for s in (RADAR, CAMERA)))
    sc, r = scene(), {"radar.hfov_deg": 70.0, "camera.hfov_deg": 100.0}
    _, cov = detect(suite, sc, r, KEY, "hard", 1.0)
    members = views(suite, sc, r, KEY, "hard", 1.0)
    both = [(t, v) for t, v in np.argwhere(np.asarray(members[0][0].p_detect) * np.asarray(members[1][0].p_detect) > 0)
            if v != 0]
    assert len(both) >= 4
    m = lambda c, t, v: np.array([[c.xx[t, v], c.xy[t, v]], [c.xy[t, v], c.yy[t, v]]])  # noqa: E731
    for t, v in both:
        for _, c in members:
            assert np.linalg.eigvalsh(m(c, t, v) - m(cov, t, v)).min() >= -1e-12


def test_gradients_match_central_differences_and_stay_finite_at_the_extremes_in_float32():
    sc = scene()
    r0 = {"radar.hfov_deg": 70.0, "radar.tx_power_dbm": 12.0, "camera.hfov_deg": 100.0, "camera.width_px": 1500.0}
    w = jnp.linspace(0.5, 1.5, 32).reshape(4, 8)

    def f(r):
        det = SUITE.detect(sc, r, KEY, temperature=2.0)
        return jnp.sum(w * det.p_detect) + 0.01 * jnp.sum(w * det.x_m) + 0.01 * jnp.sum(w[::-1] * det.y_m)

    value, grad = jax.jit(f), jax.jit(jax.grad(f))(r0)
    for name, g in grad.items():
        h = 1e-5 * abs(r0[name])
        up, down = r0 | {name: r0[name] + h}, r0 | {name: r0[name] - h}
        np.testing.assert_allclose(float(g), (float(value(up)) - float(value(down))) / (2 * h), rtol=1e-5, atol=1e-9)
    # A blind camera and a 359 deg radar: p of 0 and 1 in float32, where log1p(-p) is -inf.
    sc32 = scene(np.float32)
    g32 = jax.jit(jax.grad(lambda r: jnp.sum(SUITE.detect(sc32, r, KEY).x_m)))({"radar.hfov_deg": 359.0,
                                                                                "camera.range_m": 1e-3})
    assert all(np.isfinite(float(v)) for v in g32.values())


def test_the_suite_passes_temperature_and_weather_to_its_members():
    sc, r = scene(), {"radar.hfov_deg": 70.0, "camera.hfov_deg": 100.0}
    weather = Weather(rain_mm_h=40.0, fog_visibility_m=150.0)
    want = detect(SUITE, sc, r, KEY, "soft", 2.0, weather)[0]
    got = sensor_detect(SUITE, sc, r, KEY, "soft", 2.0, weather)
    for a in ("p_detect", "x_m", "y_m"):
        np.testing.assert_array_equal(np.asarray(getattr(got, a)), np.asarray(getattr(want, a)))
    plain = eqx.filter_jit(lambda s, sc, r, k: s.detect_with_covariance(sc, r, k)[0])(SUITE, sc, r, KEY)
    np.testing.assert_array_equal(np.asarray(plain.p_detect), np.asarray(detect(SUITE, sc, r, KEY, "soft", 1.0)[0].p_detect))
    for t, w in ((2.0, CLEAR), (1.0, weather)):  # and each matters here
        assert np.abs(np.asarray(detect(SUITE, sc, r, KEY, "soft", t, w)[0].p_detect) - np.asarray(want.p_detect)).max() > 1e-3


def test_suite_draws_given_as_arrays_are_the_keys_draws():
    # member i draws from split(key, M)[i]; the draws [M, 2, T, V] may be given instead (float32 too)
    sc = scene()
    run = eqx.filter_jit(lambda s, sc, k: s.detect(sc, {}, k))
    for suite in (SUITE, Suite((RADAR, CAMERA, RADAR), names=("radar", "camera", "corner"))):
        draws = jnp.stack([sensors.measurement_noise(k, sc) for k in jax.random.split(KEY, len(suite.members))])
        by_key, by_draws = run(suite, sc, KEY), run(suite, sc, draws)
        by_draws32, want32 = run(suite, sc, draws.astype(jnp.float32)), run(suite, sc, draws.astype(jnp.float32).astype(draws.dtype))
        for a in ("p_detect", "x_m", "y_m"):
            np.testing.assert_allclose(np.asarray(getattr(by_draws, a)), np.asarray(getattr(by_key, a)), rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(np.asarray(getattr(by_draws32, a)), np.asarray(getattr(want32, a)), rtol=1e-12,
                                       atol=1e-12)
    with pytest.raises(InputError, match=r"\(2, 2, 4, 8\)"):
        SUITE.detect(sc, {}, jnp.zeros((2, 4, 8)))


def test_names_specs_and_refusals():
    assert SUITE.kind == "suite" and SUITE.mount_x_m == 4.2  # the farthest-forward member's
    specs = SUITE.param_specs()
    names = [s.name for s in specs]  # 5 radar and 4 camera parameters of their own, 3 of mounting each
    assert names[:2] == ["radar.hfov_deg", "radar.vfov_deg"] and "camera.width_px" in names and len(names) == 15
    docs = {s.name: s.doc for s in specs}
    assert docs["radar.hfov_deg"].startswith("radar: ") and docs["camera.width_px"].startswith("camera: ")
    assert SUITE.spec("camera.width_px").unit == "px"
    assert Suite((RADAR, RADAR), names=("front", "corner")).spec("corner.range_m").default == 100.0
    with pytest.raises(InputError, match="'hfov_deg'"):
        SUITE.spec("hfov_deg")
    with pytest.raises(InputError, match="radar"):
        Suite((RADAR, RADAR))
    with pytest.raises(InputError, match="radar") as err:  # the name given twice, not the first
        Suite((CAMERA, RADAR, RADAR))
    assert "camera" not in str(err.value)
    assert len(Suite((RADAR,) * 6, names=[f"r{i}" for i in range(6)]).members) == 6  # at most 6
    with pytest.raises(InputError, match="7"):
        Suite((RADAR,) * 7, names=[f"r{i}" for i in range(7)])
    for bad in ("front.left", ".", ""):
        with pytest.raises(InputError, match=repr(bad)):
            Suite((RADAR,), names=(bad,))
    assert Suite((RADAR,), names=("front_left",)).names == ("front_left",)
    with pytest.raises(InputError, match="toy"):  # a member without measurement_covariance cannot be fused
        Suite((RADAR, ToySensor())).detect(scene(), {}, KEY)
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(InputError, match="temperature"):
            alone(RADAR).member_views(scene(), {}, KEY, temperature=bad)


def _cars():
    """Ego at 0 and cars 5, 20 and 40 m ahead (two frames)."""
    x = np.array([[0.0, 5.0, 20.0, 40.0], [0.5, 5.5, 20.5, 40.5]])
    return make_scene(x, np.zeros_like(x), kind=[CAR] * 4)


def test_a_custom_member_gets_its_r_and_is_fused_with_its_own_covariance():
    suite = Suite((ToyWithCovariance(),), names=("front",))
    near = suite.detect(_cars(), {"front.range_m": 10.0}, KEY, mode="hard")
    far = suite.detect(_cars(), {"front.range_m": 30.0}, KEY, mode="hard")
    np.testing.assert_array_equal(np.asarray(near.p_detect), [[1, 1, 0, 0]] * 2)  # the ego is known
    np.testing.assert_array_equal(np.asarray(far.p_detect), [[1, 1, 1, 0]] * 2)
    (det, cov), = suite.member_views(_cars(), None, KEY, mode="hard")
    np.testing.assert_array_equal(np.asarray(det.p_detect), [[1, 1, 1, 1]] * 2)  # all within 50 m
    assert (float(cov.xx[0, 1]), float(cov.xy[1, 2]), float(cov.yy[1, 3])) == (4.0, 1.0, 9.0)
    # soft by default at temperature 1: the toy's p is sigmoid(margin / (2 T)); 21 m of range for
    # the car 20 m ahead: sigmoid(1/2) = 0.6224593 (at T = 2 sigmoid(1/4) = 0.5621765)
    (soft, _), = suite.member_views(_cars(), {"front.range_m": 21.0}, KEY)
    np.testing.assert_allclose(np.asarray(soft.p_detect)[:, 2], [1.0 / (1.0 + math.exp(-0.5))] * 2, rtol=1e-12)
    with pytest.raises(ValueError):  # one drawn probability per member
        sensors.fuse_members(_cars(), [(det, cov)] * 2, [det.p_detect])


class ShowsWhatItIsHanded(ToySensor):
    """The toy sensor whose view shows its inputs: rain halves its p of the other vehicles; its
    covariance is xx = range_m, xy = the rain rate, yy = the temperature (soft) or 100 (hard)."""

    def _detect(self, scene, r, noise, mode, temperature, weather):
        det = super()._detect(scene, r, noise, mode, temperature, weather)
        factor = 0.5 if weather.rain_mm_h > 0 else 1.0
        return Detections(det.p_detect.at[..., 1:].multiply(factor), det.x_m, det.y_m)

    def measurement_covariance(self, scene, r, mode, temperature, weather) -> Covariance:
        ones = jnp.ones(scene.x_m.shape)
        return Covariance(xx=r["range_m"] * ones, xy=weather.rain_mm_h * ones,
                          yy=(temperature if mode == "soft" else 100.0) * ones)


@pytest.mark.parametrize("mode", ["soft", "hard"])
def test_a_custom_member_is_handed_r_mode_temperature_and_weather(mode):
    suite, sc = Suite((ShowsWhatItIsHanded(),), names=("toy",)), make_scene([[0.0, 5.0]], [[0.0, 0.0]])
    (clear, _), = suite.member_views(sc, {"toy.range_m": 7.0}, KEY, mode=mode, temperature=3.0)
    (det, cov), = suite.member_views(sc, {"toy.range_m": 7.0}, KEY, mode=mode, temperature=3.0,
                                     weather=Weather(rain_mm_h=25.0))
    assert float(clear.p_detect[0, 1]) > 0.5  # the car 5 m ahead is within the 7 m range
    assert float(det.p_detect[0, 1]) == pytest.approx(0.5 * float(clear.p_detect[0, 1]), rel=1e-12)
    yy = 3.0 if mode == "soft" else 100.0
    assert (float(cov.xx[0, 1]), float(cov.xy[0, 1]), float(cov.yy[0, 1])) == (7.0, 25.0, yy)
