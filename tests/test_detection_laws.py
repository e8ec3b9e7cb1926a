"""Detection as a physical probability: the Swerling I radar and the confidence camera against
closed forms worked by hand, the laws' floors, clips and bounds, the law of large numbers against
simulated physical detection events, float64 central differences, and every parameter's extremes.

Numbers: Pd = Pfa^(1 / (1 + SNR)); the Gaussian beam's loss constant
10 log10(e) * 4 ln 2 = 12.0411998 dB; Phi written with erfc.
"""

from __future__ import annotations

import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _sensor_scenes import covered, interval, make_scene, phi
from test_sensor_gradients import (
    POINTS,
    at_extremes,
    extreme_scene,
    extreme_settings,
    gradient_scene,
)
from test_sensor_gradients import value as weighted_detections
from test_sensor_gradients import value_and_grad as weighted_detections_and_grad

from diffsense import config as cfg
from diffsense import sensors
from diffsense.runtime import InputError

RADAR = cfg.replace(sensors.load_config("radar"), detection=sensors.RadarDetection(law="swerling1"))
CAMERA = cfg.replace(sensors.load_config("camera"), detection=sensors.CameraDetection(law="confidence"))
p_detect = jax.jit(sensors.p_detect, static_argnames=("config", "mode"))
BEAM_DB = 12.0411998


@pytest.mark.parametrize("snr_db, pfa, pd", [
    (10.0, 1e-6, 0.28480358684358015), (20.0, 1e-6, 0.8721557721439983), (13.0, 1e-4, 0.6443073948501822),
    (0.0, 1e-2, 0.1),  # SNR 1: Pd = sqrt(Pfa)
    (30.0, 1e-8, 0.9817660095852473), (-10.0, 0.1, 0.12328467394420663),
    # SNR = ln Pfa / ln Pd - 1 = 130.13 (21.14 dB): the single-look Swerling I requirement for Pd 0.9
    (21.143643201915836, 1e-6, 0.9),
])
def test_swerling1_closed_form(snr_db, pfa, pd):
    assert math.exp(float(sensors.swerling1_log_pd(jnp.asarray(snr_db), pfa))) == pytest.approx(pd, rel=1e-12)


def test_the_gaussian_beam_is_3_db_down_at_half_the_hfov_and_its_width_floored_at_1e_6_deg():
    loss = np.asarray(sensors.gaussian_beam_loss_db(jnp.deg2rad(jnp.asarray([0.0, 15.0, -15.0, 30.0])), 30.0))
    np.testing.assert_allclose(loss, [0.0, 3.010299956639812, 3.010299956639812, 12.041199826559248], rtol=1e-12)
    # HFOV 0 (or below): 1e-6 deg = 1.7453293e-8 rad; 1e-9 rad off boresight: 12.0412 * 0.0032828 dB
    floor = BEAM_DB * (1e-9 / 1.7453293e-8) ** 2
    for hfov in (0.0, -5.0, 1e-6):
        assert float(sensors.gaussian_beam_loss_db(jnp.asarray(1e-9), jnp.asarray(hfov))) == pytest.approx(floor, rel=1e-6)
    assert float(sensors.gaussian_beam_loss_db(jnp.asarray(1e-9), jnp.asarray(2e-6))) == pytest.approx(0.25 * floor, rel=1e-6)


@pytest.mark.parametrize("gap_m, sigma_m, z", [
    (1e-3, 0.0, 1.0),                    # no noise: the 1 mm floor alone
    (3e-3, 3e-3, 3 / math.sqrt(10.0)),   # sqrt(3^2 + 1^2) mm
    (-2.0, 1.0, -2.0 / math.sqrt(1.0 + 1e-6)),
])
def test_the_range_cut_noise_has_a_1_mm_floor_in_quadrature(gap_m, sigma_m, z):
    got = float(sensors.log_reported_below(jnp.asarray(100.0), jnp.asarray(100.0 - gap_m), jnp.asarray(sigma_m)))
    assert math.exp(got) == pytest.approx(phi(z), rel=1e-9)


def test_in_fov_fraction_on_both_edges():
    edge, one = math.radians(15.0), math.radians(1.0)  # HFOV 30 deg
    az = jnp.asarray([0.0, edge, edge + 0.5 * one, edge + 2 * one, -edge - 0.5 * one, 0.0, edge, -edge, edge + 1e-9])
    half = jnp.asarray([one, one, one, one, one, math.radians(20.0), 0.0, 0.0, 0.0])
    # half, a quarter, none of a 2 deg car; the left edge; a 40 deg car shows the image's 30 deg;
    # zero width exactly on either edge is inside, just past it outside
    np.testing.assert_allclose(np.asarray(sensors.in_fov_fraction(az, half, 30.0)),
                               [1.0, 0.5, 0.25, 0.0, 0.25, 0.75, 1.0, 1.0, 0.0], atol=1e-12)
    # 0.2 mrad wide vehicles in float32: (az + half) - (az - half) rounds past the width; still <= 1
    az32 = jnp.linspace(0.1, 0.5, 101, dtype=jnp.float32)
    got = np.asarray(sensors.in_fov_fraction(az32, jnp.full_like(az32, 1e-4), 120.0))
    assert got.dtype == np.float32 and got.max() <= 1.0 and got.min() > 0.9998


def test_the_confidence_mean_clips_the_visible_fraction_to_0_1():
    # width 14 px: size = sigmoid((14 - 10) / 2) = 0.8807971; at 10 px half of 0.95
    got = np.asarray(sensors.confidence_mean(jnp.asarray([14.0, 14.0, 14.0, 10.0]), jnp.asarray([1.5, -0.5, 0.5, 1.0]),
                                             confidence_max=0.95, width50_px=10.0, width_scale_px=2.0))
    np.testing.assert_allclose(got, [0.95 * 0.8807971, 0.0, 0.95 * 0.8807971 * 0.5, 0.475], rtol=1e-7)
    assert math.exp(float(sensors.log_confidence_above(0.7, 0.6, 0.1))) == pytest.approx(phi(1.0), rel=1e-12)


def test_the_laws_parameters_are_checked_at_their_bounds():
    for pfa in (1e-300, 0.5, 1.0 - 1e-16):
        assert sensors.RadarDetection(law="swerling1", pfa=pfa).pfa == pfa
    for pfa in (0.0, 1.0, -1e-6, 1.5):
        with pytest.raises(InputError, match="pfa"):
            sensors.RadarDetection(law="swerling1", pfa=pfa)
    for ok in (dict(confidence_max=1.0), dict(confidence_max=1e-9), dict(threshold=0.0), dict(threshold=1.0),
               dict(width_scale_px=1e-9), dict(sigma=1e-9)):
        law = sensors.CameraDetection(law="confidence", **ok)
        assert all(getattr(law, k) == v for k, v in ok.items())
    for bad in (dict(confidence_max=0.0), dict(confidence_max=1.0 + 1e-9), dict(threshold=-1e-9),
                dict(threshold=1.0 + 1e-9), dict(width_scale_px=0.0), dict(sigma=0.0), dict(width_scale_px=-1.0),
                dict(sigma=-1.0)):
        with pytest.raises(InputError, match=next(iter(bad))):
            sensors.CameraDetection(law="confidence", **bad)


def pair(x_m, y_m, **kw):
    return make_scene([[0.0, x_m]], [[0.0, y_m]], **kw)


def test_the_radar_at_the_beam_edge_loses_6_db_two_way_and_cuts_on_the_measured_range():
    params = sensors.make_params(RADAR, hfov_deg=30.0)
    az = math.radians(15.0)
    boresight = float(sensors.radar_snr_db(jnp.asarray(50.0), 10.0, params, RADAR))
    s = 10 ** ((boresight - 6.020599913279624) / 10)
    got = float(p_detect(pair(RADAR.mount_x_m + 50.0 * math.cos(az), 50.0 * math.sin(az)), params, RADAR)[0, 1])
    assert got == pytest.approx(1e-6 ** (1 / (1 + s)), rel=1e-6)  # the range cut at 100 m is ~1 here
    # At exactly range_m the measured range is below it half the time.
    params = sensors.make_params(RADAR, hfov_deg=10.0, range_m=60.0)
    snr = float(sensors.radar_snr_db(jnp.asarray(60.0), 10.0, params, RADAR))
    assert float(p_detect(pair(RADAR.mount_x_m + 60.0, 0.0), params, RADAR)[0, 1]) == pytest.approx(
        0.5 * 1e-6 ** (1 / (1 + 10 ** (snr / 10))), rel=1e-6)


def test_the_camera_sees_half_a_car_on_the_image_edge():
    # 40 m away (size term 1 - 2e-5), centre on the edge: mean 0.95 * 0.5, p = Phi(-1.25)
    az = math.radians(15.0)
    scene = pair(CAMERA.mount_x_m + 40.0 * math.cos(az), 40.0 * math.sin(az), heading_rad=[[0.0, az]])
    assert float(p_detect(scene, sensors.make_params(CAMERA, hfov_deg=30.0), CAMERA)[0, 1]) == pytest.approx(
        0.1056497736668553, rel=2e-4)


def lln(p_smooth, hits, n):
    """The hard draws' mean within 3 standard errors of the smooth probability."""
    se = math.sqrt(max(p_smooth * (1 - p_smooth), 1e-12) / n)
    assert abs(hits / n - p_smooth) < 3 * se, (hits / n, p_smooth, se)


# (car or occluder centres (x, y), parameter changes); the last car is on an edge. Hard mode: the
# law's p with the exact occlusion geometry, which the footprint's corners give by hand.
CASES = {
    "fov_edge": ([(4.2 + 60 * math.cos(math.radians(20)), 60 * math.sin(math.radians(20)))], {"hfov_deg": 40.0}),
    "range": ([(4.2 + 99.8, 0.0)], {"hfov_deg": 60.0}),
    "occlusion": ([(24.0, 1.2), (49.0, 0.0)], {"hfov_deg": 120.0}),
}
N_DRAWS = 200_000


def by_hand(case, config):
    """(scene, params, hard p, range [m], angular interval (lo, hi) [rad], hidden fraction) of the last car."""
    cars, changes = CASES[case]
    if config is CAMERA and case == "range":
        changes = dict(changes, range_m=104.0)  # depth noise ~20 m at 104 m
    scene = make_scene([[0.0] + [c[0] for c in cars]], [[0.0] + [c[1] for c in cars]])
    params = sensors.make_params(config, **changes)
    p = float(np.asarray(p_detect(scene, params, config, mode="hard"))[0, -1])
    assert 0.05 < p < 0.95  # on an edge, not a certainty
    sx, (x, y) = config.mount_x_m, cars[-1]
    hidden = covered(sx, cars[-1], cars[0]) if len(cars) > 1 else 0.0
    return p, params, math.hypot(x - sx, y), interval(sx, x, y), hidden


@pytest.mark.parametrize("case", list(CASES))
def test_radar_hard_draws_converge_to_the_law(case):
    p, params, r, (lo, hi), hidden = by_hand(case, RADAR)
    az = 0.5 * (lo + hi)
    snr_db = (float(sensors.radar_snr_db(jnp.asarray(r), 10.0, params, RADAR)) - 15.0 * hidden
              - 2 * float(sensors.gaussian_beam_loss_db(jnp.asarray(az), params.hfov_deg)))
    s = 10 ** (snr_db / 10)
    sigma = math.hypot(0.4, 1.8 * 10 ** (-snr_db / 20) / math.sqrt(2))  # Table I's accuracy and thermal noise
    # The physical event: complex Gaussian echo of power SNR plus unit complex Gaussian noise,
    # square-law detected against -ln Pfa; and the measured range (Gaussian) <= range_m.
    rng = np.random.default_rng(1)
    echo = math.sqrt(s / 2) * (rng.standard_normal(N_DRAWS) + 1j * rng.standard_normal(N_DRAWS))
    noise = math.sqrt(0.5) * (rng.standard_normal(N_DRAWS) + 1j * rng.standard_normal(N_DRAWS))
    reported = r + math.sqrt(sigma**2 + 1e-6) * rng.standard_normal(N_DRAWS) <= params.range_m
    lln(p, int(np.sum((np.abs(echo + noise) ** 2 > -math.log(1e-6)) & reported)), N_DRAWS)


@pytest.mark.parametrize("case", list(CASES))
def test_camera_hard_draws_converge_to_the_law(case):
    p, params, r, (lo, hi), hidden = by_hand(case, CAMERA)
    edge = 0.5 * math.radians(params.hfov_deg)
    in_image = max(0.0, min(hi, edge) - max(lo, -edge)) / (hi - lo)
    width_px = float(sensors.camera_px_per_rad(params)) * (hi - lo)
    mean = 0.95 * in_image * (1 - hidden) / (1 + math.exp(-(width_px - 10.0) / 2.0))
    depth_sigma = r**2 * 0.5 / (float(sensors.camera_px_per_rad(params)) * 0.12)
    rng = np.random.default_rng(2)
    confident = mean + 0.1 * rng.standard_normal(N_DRAWS) >= 0.6
    reported = r + math.sqrt(depth_sigma**2 + 1e-6) * rng.standard_normal(N_DRAWS) <= params.range_m
    lln(p, int(np.sum(confident & reported)), N_DRAWS)


def _p_of(config, scene, name):
    def f(value):
        return jnp.sum(sensors.p_detect(scene, sensors.with_param(config.params, name, value), config))
    return jax.jit(jax.value_and_grad(f))


@pytest.mark.parametrize("config", [RADAR, CAMERA], ids=["radar", "camera"])
@pytest.mark.parametrize("name, point", [("hfov_deg", 37.0), ("range_m", 99.0)])
def test_the_gradient_matches_float64_central_differences(config, name, point):
    scene = make_scene([[0.0, 24.0, 49.0, 4.2 + 60 * math.cos(0.3), 104.0]], [[0.0, 1.2, 0.0, 60 * math.sin(0.3), -3.0]])
    f = _p_of(config, scene, name)
    g = float(f(jnp.asarray(point))[1])
    h = 1e-5 * point
    fd = (float(f(jnp.asarray(point + h))[0]) - float(f(jnp.asarray(point - h))[0])) / (2 * h)
    assert abs(g) > 1e-4 and g == pytest.approx(fd, rel=1e-5)


@pytest.mark.parametrize("name, config", [("radar", RADAR), ("camera", CAMERA)], ids=["radar", "camera"])
def test_every_parameter_matches_float64_central_differences(name, config):
    # Through the law's p and the measured positions; the camera at 116 deg puts the car at -60 deg
    # on the image's edge, where the yaw moves its visible fraction.
    params = sensors.make_params(config, **(POINTS[name] | ({"hfov_deg": 116.0} if name == "camera" else {})))
    scene = gradient_scene()
    _, grad = weighted_detections_and_grad(params, scene, config, 1.0)
    for spec in sensors.param_specs(name, config):
        r = getattr(params, spec.name)
        h = 1e-6 * abs(r)  # the range cut's width is the 0.4 m range noise, not a temperature
        up = weighted_detections(sensors.with_param(params, spec.name, r + h), scene, config, 1.0)
        down = weighted_detections(sensors.with_param(params, spec.name, r - h), scene, config, 1.0)
        fd = float(up - down) / (2 * h)
        assert abs(fd) > 1e-4 / abs(r), f"{spec.name}: saturated, the check would be empty"
        assert float(getattr(grad, spec.name)) == pytest.approx(fd, rel=1e-5), spec.name


@pytest.mark.parametrize("pfa", [1e-12, 1e-6, 0.1])
def test_no_nan_or_inf_at_any_extreme(pfa):
    radar = cfg.replace(RADAR, detection=sensors.RadarDetection(law="swerling1", pfa=pfa))
    # vehicles at 0.1 m, on the ego, far off-axis, behind, and 1000 m ahead
    scene = make_scene([[0.0, 4.3, 4.2, 10.0, -50.0, 1004.2]], [[0.0, 0.0, 0.0, 30.0, 0.0, 0.0]])
    for config in (radar, CAMERA):
        for name, values in (("hfov_deg", (0.01, 1.0, 180.0, 360.0)), ("range_m", (0.1, 50.0, 1000.0))):
            f = _p_of(config, scene, name)
            for v in values:
                value, grad = f(jnp.asarray(v))
                assert np.isfinite(float(value)) and np.isfinite(float(grad)), (config.detection.law, name, v)
    grads = jax.vmap(jax.grad(lambda s: sensors.swerling1_log_pd(s, pfa)))(jnp.asarray([-1e4, -300.0, 0.0, 300.0, 1e4]))
    assert np.isfinite(np.asarray(grads)).all()


LAW_EXTREMES = {"radar pfa 1e-12": cfg.replace(RADAR, detection=sensors.RadarDetection(law="swerling1", pfa=1e-12)),
                "radar pfa 0.1": cfg.replace(RADAR, detection=sensors.RadarDetection(law="swerling1", pfa=0.1)),
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
    config = LAW_EXTREMES[case]
    raw, temps = extreme_settings(case.split()[0])
    params = type(config.params)(**{k: jnp.asarray(v, dtype) for k, v in raw.items()})
    soft, empty, hard = at_extremes(params, jnp.asarray(temps, dtype), extreme_scene(dtype), config)
    for leaf in jax.tree.leaves((soft, empty, hard)):
        assert leaf.dtype == dtype and np.all(np.isfinite(np.asarray(leaf))), case
    for p in (soft[1].p_detect, hard):
        assert np.all((np.asarray(p) >= 0) & (np.asarray(p) <= 1))
    np.testing.assert_array_equal(empty[1].p_detect, 1.0)  # the ego alone
    assert np.any((np.asarray(hard) > 0) & (np.asarray(hard) < 1))  # the law's p, not a 0/1 gate


def test_the_physical_profile_ships_the_physical_laws_and_the_paper_profile_the_threshold():
    for name, law in (("radar", "swerling1"), ("camera", "confidence")):
        assert sensors.load_config(name).detection.law == law
        assert sensors.load_config(name, profile="paper").detection.law == "threshold"
    assert sensors.load_config("radar") == RADAR and sensors.load_config("camera") == CAMERA
    # each law's config switches the law and nothing else, in either profile
    laws = Path(__file__).resolve().parents[1] / "configs" / "sensors" / "laws"
    for profile in ("physical", "paper"):
        for name, files in (("radar", ("radar_swerling1", "radar_threshold")), ("camera", ("camera_confidence", "camera_threshold"))):
            base = sensors.load_config(name, profile=profile)
            for file in files:
                switched = sensors.load_config(name, laws / f"{file}.toml", profile)
                assert cfg.replace(switched, detection=base.detection) == base
                assert switched.detection.law == ("threshold" if "threshold" in file else sensors.load_config(name).detection.law)
