"""Detection as a physical probability (`diffsense.sensors._laws`): the Swerling I radar and the
confidence camera against closed forms worked by hand, the law of large numbers against
simulated physical detection events, float64 central differences, and every parameter's extremes."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_sensor_grad import POINTS, _at_extremes, _extreme_settings, extreme_scene, gradient_scene
from test_sensor_grad import value as weighted_detections
from test_sensor_grad import value_and_grad as weighted_detections_and_grad
from test_sensor_scenes import make_scene

from diffsense import config as cfg
from diffsense import sensors as sensor
from diffsense.sensors._geometry import Tracks, polar, vehicle_occlusion
from diffsense.sensors._laws import (
    CameraDetection,
    RadarDetection,
    gaussian_beam_loss_db,
    in_fov_fraction,
    swerling1_log_pd,
)

RADAR = cfg.replace(sensor.load_config("radar"), detection=RadarDetection(law="swerling1"))
CAMERA = cfg.replace(sensor.load_config("camera"), detection=CameraDetection(law="confidence"))
p_detect = jax.jit(sensor.p_detect, static_argnames=("config", "mode"))


@pytest.mark.parametrize("snr_db, pfa, pd", [
    # Pd = Pfa^(1/(1+SNR)) worked by hand (SNR linear = 10^(dB/10)): 1e-6^(1/11) = e^(-13.8155/11)
    (10.0, 1e-6, 0.28480358684358015), (20.0, 1e-6, 0.8721557721439983),
    (13.0, 1e-4, 0.6443073948501822), (0.0, 1e-2, 0.1),  # SNR 1: Pd = sqrt(Pfa)
    (30.0, 1e-8, 0.9817660095852473), (-10.0, 0.1, 0.12328467394420663),
])
def test_swerling1_closed_form(snr_db, pfa, pd):
    assert math.exp(float(swerling1_log_pd(jnp.asarray(snr_db), pfa))) == pytest.approx(pd, rel=1e-12)


def test_swerling1_needs_21_1_db_for_pd_0_9_at_pfa_1e_6():
    # Inverting the law: SNR = ln Pfa / ln Pd - 1 = 130.13 (21.14 dB), the single-look
    # Swerling I requirement quoted in radar texts (~8 dB above the steady target's 13.2 dB).
    assert math.exp(float(swerling1_log_pd(jnp.asarray(21.143643201915836), 1e-6))) == pytest.approx(0.9, rel=1e-12)


def test_gaussian_beam_is_3_db_down_at_half_the_hfov():
    az = jnp.deg2rad(jnp.asarray([0.0, 15.0, -15.0, 30.0]))
    loss = np.asarray(gaussian_beam_loss_db(az, 30.0))
    np.testing.assert_allclose(loss, [0.0, 3.010299956639812, 3.010299956639812, 12.041199826559248], rtol=1e-12)


def test_in_fov_fraction_of_a_vehicle_on_the_edge():
    half = math.radians(1.0)
    frac = np.asarray(in_fov_fraction(jnp.asarray([0.0, math.radians(15.0), math.radians(15.5), math.radians(17.0)]),
                                      half, 30.0))
    np.testing.assert_allclose(frac, [1.0, 0.5, 0.25, 0.0], atol=1e-12)
    # zero width: the centre decides
    np.testing.assert_array_equal(np.asarray(in_fov_fraction(jnp.asarray([0.1, 0.3]), 0.0, 30.0)), [1.0, 0.0])


def _pair(x_m, y_m, **kw):
    """Ego at the origin and one car at (x_m, y_m)."""
    return make_scene([[0.0, x_m]], [[0.0, y_m]], **kw)


def _radar_snr(scene, params, config, mode="soft"):
    """The SNR [dB] the radar law sees: link budget, two-way beam loss, occlusion loss."""
    tracks = Tracks.of(scene)
    mount = config.mount_x_m
    range_m, az = polar(tracks, mount)
    _, shadow = vehicle_occlusion(tracks, range_m, az, mount, mode, config.temperature.near_m,
                                  config.temperature.overlap_deg)
    rcs = sensor.radar_rcs_dbsm(tracks.kind, config)
    snr = sensor.radar_snr_db(range_m, rcs, params, config)
    return (snr - config.occlusion_loss_db * shadow - 2 * gaussian_beam_loss_db(az, params.hfov_deg)), range_m


def test_radar_at_the_beam_edge_loses_6_db_two_way():
    params = sensor.make_params(RADAR, hfov_deg=30.0)
    x = 50.0
    az = math.radians(15.0)
    scene = _pair(RADAR.mount_x_m + x * math.cos(az), x * math.sin(az))
    p = float(p_detect(scene, params, RADAR)[0, 1])
    boresight = float(sensor.radar_snr_db(jnp.asarray(x), 10.0, params, RADAR))
    s = 10 ** ((boresight - 6.020599913279624) / 10)
    assert p == pytest.approx(1e-6 ** (1 / (1 + s)), rel=1e-6)  # the range cut at 100 m is ~1 here


def test_radar_range_cut_is_on_the_measured_range():
    # At exactly range_m the measured range is below it half the time.
    params = sensor.make_params(RADAR, hfov_deg=10.0, range_m=60.0)
    scene = _pair(RADAR.mount_x_m + 60.0, 0.0)
    snr = float(sensor.radar_snr_db(jnp.asarray(60.0), 10.0, params, RADAR))
    pd = 1e-6 ** (1 / (1 + 10 ** (snr / 10)))
    assert float(p_detect(scene, params, RADAR)[0, 1]) == pytest.approx(0.5 * pd, rel=1e-6)


def test_camera_confidence_on_the_image_edge():
    # A car far enough to be 30+ px wide (size term 1 - 2e-5) whose centre sits on the edge:
    # half of it is in the image, mean confidence 0.95 * 0.5, p = Phi((0.475 - 0.6) / 0.1) = Phi(-1.25).
    params = sensor.make_params(CAMERA, hfov_deg=30.0)
    x, az = 40.0, math.radians(15.0)
    scene = _pair(CAMERA.mount_x_m + x * math.cos(az), x * math.sin(az), heading_rad=[[0.0, az]])
    assert float(p_detect(scene, params, CAMERA)[0, 1]) == pytest.approx(0.1056497736668553, rel=2e-4)


def _occluded_scene():
    """Ego, a car 20 m ahead 1.2 m to the left covering part of a car 45 m ahead."""
    return make_scene([[0.0, 24.0, 49.0]], [[0.0, 1.2, 0.0]])


def _lln(p_smooth, hits, n):
    """The hard draws' mean within 3 standard errors of the smooth probability."""
    se = math.sqrt(max(p_smooth * (1 - p_smooth), 1e-12) / n)
    assert abs(hits / n - p_smooth) < 3 * se, (hits / n, p_smooth, se)


CASES = {  # name: (scene, parameter changes)
    "fov_edge": (_pair(4.2 + 60 * math.cos(math.radians(20)), 60 * math.sin(math.radians(20))), {"hfov_deg": 40.0}),
    "range": (_pair(4.2 + 99.8, 0.0), {"hfov_deg": 60.0}),
    "occlusion": (_occluded_scene(), {"hfov_deg": 120.0}),
}


@pytest.mark.parametrize("case", list(CASES))
def test_radar_hard_draws_converge_to_the_smooth_probability(case):
    scene, changes = CASES[case]
    params = sensor.make_params(RADAR, **changes)
    p = np.asarray(p_detect(scene, params, RADAR))[0, -1]
    snr_db, range_m = _radar_snr(scene, params, RADAR)
    s, r = 10 ** (float(snr_db[-1, 0]) / 10), float(range_m[-1, 0])
    assert 0.05 < p < 0.95  # the case is on an edge, not a certainty
    # The physical event: complex Gaussian echo of power SNR plus unit complex Gaussian noise,
    # square-law detected against -ln Pfa; the measured range (Gaussian, its sigma) <= range_m.
    n = 200_000
    rng = np.random.default_rng(1)
    echo = math.sqrt(s / 2) * (rng.standard_normal(n) + 1j * rng.standard_normal(n))
    noise = math.sqrt(0.5) * (rng.standard_normal(n) + 1j * rng.standard_normal(n))
    thermal = 10 ** (-float(snr_db[-1, 0]) / 20) / math.sqrt(2)
    sigma = math.sqrt(RADAR.range_accuracy_m**2 + (RADAR.range_resolution_m * thermal) ** 2 + 1e-6)
    reported = r + sigma * rng.standard_normal(n) <= params.range_m
    hits = int(np.sum((np.abs(echo + noise) ** 2 > -math.log(RADAR.detection.pfa)) & reported))
    _lln(float(p), hits, n)


@pytest.mark.parametrize("case", list(CASES))
def test_camera_hard_draws_converge_to_the_smooth_probability(case):
    scene, changes = CASES[case]
    changes = dict(changes, range_m=104.0) if case == "range" else changes  # depth noise ~20 m at 104 m
    params = sensor.make_params(CAMERA, **changes)
    p = float(np.asarray(p_detect(scene, params, CAMERA))[0, -1])
    assert 0.05 < p < 0.95
    tracks = Tracks.of(scene)
    mount = CAMERA.mount_x_m
    range_m, az = polar(tracks, mount)
    half, hidden = vehicle_occlusion(tracks, range_m, az, mount, "soft", CAMERA.temperature.near_m,
                                     CAMERA.temperature.overlap_deg)
    k = float(sensor.camera_px_per_rad(params))
    width_px = k * 2 * float(half[-1, 0])
    visible = float(in_fov_fraction(az[-1, 0], half[-1, 0], params.hfov_deg)) * (1 - float(hidden[-1, 0]))
    law = CAMERA.detection
    mean = law.confidence_max * visible / (1 + math.exp(-(width_px - law.width50_px) / law.width_scale_px))
    depth_sigma = float(sensor.camera_depth_sigma_m(range_m[-1, 0], params, CAMERA))
    n = 200_000
    rng = np.random.default_rng(2)
    confident = mean + law.sigma * rng.standard_normal(n) >= law.threshold
    reported = float(range_m[-1, 0]) + math.sqrt(depth_sigma**2 + 1e-6) * rng.standard_normal(n) <= params.range_m
    _lln(p, int(np.sum(confident & reported)), n)


def _p_of(config, scene, name):
    def f(value):
        params = sensor.with_param(config.params, name, value)
        return jnp.sum(sensor.p_detect(scene, params, config))
    return jax.jit(jax.value_and_grad(f))


@pytest.mark.parametrize("config", [RADAR, CAMERA], ids=["radar", "camera"])
@pytest.mark.parametrize("name, point", [("hfov_deg", 37.0), ("range_m", 99.0)])
def test_gradient_matches_float64_central_differences(config, name, point):
    scene = make_scene([[0.0, 24.0, 49.0, 4.2 + 60 * math.cos(0.3), 104.0]],
                       [[0.0, 1.2, 0.0, 60 * math.sin(0.3), -3.0]])
    f = _p_of(config, scene, name)
    g = float(f(jnp.asarray(point))[1])
    h = 1e-5 * point
    fd = (float(f(jnp.asarray(point + h))[0]) - float(f(jnp.asarray(point - h))[0])) / (2 * h)
    assert abs(g) > 1e-4  # the point is chosen where the parameter matters
    assert g == pytest.approx(fd, rel=1e-5)


@pytest.mark.parametrize("pfa", [1e-12, 1e-6, 0.1])
def test_no_nan_or_inf_at_any_extreme(pfa):
    radar = cfg.replace(RADAR, detection=RadarDetection(law="swerling1", pfa=pfa))
    # vehicles at 0.1 m, on the ego, far off-axis, behind, and 1000 m ahead
    scene = make_scene([[0.0, 4.3, 4.2, 10.0, -50.0, 1004.2]], [[0.0, 0.0, 0.0, 30.0, 0.0, 0.0]])
    for config in (radar, CAMERA):
        for name, values in (("hfov_deg", (0.01, 1.0, 180.0, 360.0)), ("range_m", (0.1, 50.0, 1000.0))):
            f = _p_of(config, scene, name)
            for v in values:
                value, grad = f(jnp.asarray(v))
                assert np.isfinite(float(value)) and np.isfinite(float(grad)), (config.detection.law, name, v)
    assert np.isfinite(np.asarray(jax.grad(lambda s: swerling1_log_pd(s, pfa))(jnp.asarray([-1e4, 0.0, 1e4])[1]))).all()
    log_pd = np.asarray(jax.vmap(jax.grad(lambda s: swerling1_log_pd(s, pfa)))(jnp.asarray([-1e4, -300.0, 300.0, 1e4])))
    assert np.isfinite(log_pd).all()


@pytest.mark.parametrize("name, config", [("radar", RADAR), ("camera", CAMERA)], ids=["radar", "camera"])
def test_every_parameter_matches_float64_central_differences(name, config):
    # Every differentiable parameter (field of view, range, power, noise figure, resolution,
    # baseline, mounting) through the law's p and the measured positions, where each matters:
    # the camera at 116 deg puts the car at -60 deg azimuth on the image's edge, where the yaw
    # moves its visible fraction (at 120 deg it is inside and the yaw's derivative is 0).
    params = sensor.make_params(config, **(POINTS[name] | ({"hfov_deg": 116.0} if name == "camera" else {})))
    scene = gradient_scene()
    _, grad = weighted_detections_and_grad(params, scene, config, 1.0)
    for spec in sensor.param_specs(name, config):
        r = getattr(params, spec.name)
        # The range cut's width is the range noise (0.4 m), not a temperature: a step of 1e-6 r
        # keeps the central difference's h^2 term below 1e-6 of the derivative there.
        h = 1e-6 * abs(r)
        up = weighted_detections(sensor.with_param(params, spec.name, r + h), scene, config, 1.0)
        down = weighted_detections(sensor.with_param(params, spec.name, r - h), scene, config, 1.0)
        fd = float(up - down) / (2 * h)
        assert abs(fd) > 1e-4 / abs(r), f"{spec.name}: saturated, the check would be empty"
        assert float(getattr(grad, spec.name)) == pytest.approx(fd, rel=1e-5), spec.name


LAW_EXTREMES = {"radar pfa 1e-12": cfg.replace(RADAR, detection=RadarDetection(law="swerling1", pfa=1e-12)),
                "radar pfa 0.1": cfg.replace(RADAR, detection=RadarDetection(law="swerling1", pfa=0.1)),
                "camera": CAMERA}


# Each case compiles its own program (~10 s): the fast suite runs float64 at the smaller Pfa and
# the camera; the larger Pfa and float32 run with the slow tests.
@pytest.mark.parametrize("case, dtype", [
    ("radar pfa 1e-12", np.float64), ("camera", np.float64),
    *(pytest.param(c, d, marks=pytest.mark.slow) for c, d in [
        ("radar pfa 0.1", np.float64), ("radar pfa 1e-12", np.float32), ("radar pfa 0.1", np.float32),
        ("camera", np.float32)]),
])
def test_every_parameter_is_finite_at_both_ends_of_its_domain(case, dtype):
    # HFOV 0.01-360 deg and range 0.1-1000 m at every temperature, and every other parameter at
    # both ends of its domain, on a scene with a car on the FOV edge, cars co-located with the
    # sensors, behind them, hidden behind a truck and 2 km away.
    config = LAW_EXTREMES[case]
    raw, temps = _extreme_settings(case.split()[0])
    params = type(config.params)(**{k: jnp.asarray(v, dtype) for k, v in raw.items()})
    soft, empty, hard = _at_extremes(params, jnp.asarray(temps, dtype), extreme_scene(dtype), config)
    for leaf in jax.tree.leaves((soft, empty, hard)):
        assert leaf.dtype == dtype and np.all(np.isfinite(np.asarray(leaf))), case
    for p in (soft[1].p_detect, hard):
        assert np.all((np.asarray(p) >= 0) & (np.asarray(p) <= 1))
    np.testing.assert_array_equal(empty[1].p_detect, 1.0)  # the ego alone
    assert np.any((np.asarray(hard) > 0) & (np.asarray(hard) < 1))  # the law's p, not a 0/1 gate


def test_both_laws_ship_off_and_the_paper_profile_keeps_the_threshold():
    for name in ("radar", "camera"):
        for profile in ("physical", "paper"):
            assert sensor.load_config(name, profile=profile).detection.law == "threshold"


def test_the_shipped_law_configs_switch_the_law_and_nothing_else():
    from pathlib import Path

    laws = Path(__file__).resolve().parents[1] / "configs" / "sensors" / "laws"
    radar = sensor.Radar.from_toml(laws / "radar_swerling1.toml").config
    camera = sensor.Camera.from_toml(laws / "camera_confidence.toml").config
    assert radar == RADAR and camera == CAMERA
