"""The radar equation and the radar's gates and noise, against hand link budgets and the radar
equation written in linear power (configs/sensors/radar.toml and the paper's Table I).

Hand budget at HFOV 30 deg, VFOV 15 deg, a car (10 dBsm) on boresight:
  Pt 14 + 2 G 34.8079 (G = 10 log10(0.6 * 4 pi / (0.523599 * 0.261799)) = 17.4039 dBi)
  + 20 log10(3.8934 mm) -48.1934 + 10 - 30 log10(4 pi) 32.9763
  - noise floor (-174 + 10 log10(25e3) 43.9794 + NF 4.8 = -125.2206 dBm) - loss 6
  = 96.858781 dB - 40 log10(R) - 2 * 0.4 dB/km * R.
`_radar_terms` (its gates, margins and noise scales) is the physics under test here.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _laws import threshold_config
from _sensor_scenes import (
    COVERED,
    ahead,
    assert_temperature_scales_the_config,
    jit_p_detect,
    make_scene,
    occlusion_scene,
    sigmoid,
)

from diffsense import config as cfg
from diffsense import sensors
from diffsense.scene import CAR, TRUCK, VAN
from diffsense.sensors._geometry import Tracks
from diffsense.sensors._radar import _radar_terms

RADAR = threshold_config("radar")  # the gates this file tests
SWERLING = cfg.replace(RADAR, detection=sensors.RadarDetection(law="swerling1"))
terms = jax.jit(lambda scene, params, config, mode="soft", weather=sensors.CLEAR:
                _radar_terms(Tracks.of(scene), params, config, mode, 1.0, weather), static_argnums=(2, 3))


def snr(range_m, config=RADAR, **params):
    return float(sensors.radar_snr_db(jnp.asarray(range_m), 10.0, sensors.make_params(config, **params), config))


def linear_snr_db(range_m, hfov_deg=30.0, vfov_deg=15.0, pt_dbm=14.0, nf_db=4.8, beam_deg=None, kt0_dbm=-174.0):
    """The radar equation in linear power [W] for a 10 m^2 target, kT0 = -174 dBm/Hz unless given."""
    lam = 299792458.0 / 77e9
    beam = beam_deg if beam_deg is not None else hfov_deg
    gain = 0.6 * 4 * math.pi / (math.radians(beam) * math.radians(vfov_deg))
    received = 10 ** (pt_dbm / 10) * 1e-3 * gain**2 * lam**2 * 10.0 / ((4 * math.pi) ** 3 * range_m**4)
    noise = 10 ** (kt0_dbm / 10) * 1e-3 * 25e3 * 10 ** (nf_db / 10)
    return 10 * math.log10(received / noise / 10 ** ((6.0 + 2 * 0.4 * range_m / 1000) / 10))


# (the far-field equation is clamped at R = 1 mm: 96.858781 + 120 = 216.858780 dB below it)
@pytest.mark.parametrize("range_m, snr_db", [(20.0, 44.801581), (50.0, 28.859981), (100.0, 16.778781),
                                             (200.0, 4.657581), (0.5, 108.899581), (0.0, 216.858780)])
def test_snr_against_the_hand_link_budget(range_m, snr_db):
    assert snr(range_m) == pytest.approx(snr_db, abs=2e-6)
    if range_m >= 1.0:  # the physical kT0 (1.380649e-23 J/K * 290 K = -173.975 dBm/Hz): 0.0248 dB lower
        kt0 = 10 * math.log10(1.380649e-23 * 290.0 * 1e3)
        assert snr(range_m) - linear_snr_db(range_m, kt0_dbm=kt0) == pytest.approx(0.0248, abs=1e-3)


@pytest.mark.parametrize("range_m, hfov, vfov, pt, nf", [
    (20.0, 30.0, 15.0, 14.0, 4.8), (73.0, 90.0, 10.0, 10.0, 6.0), (150.0, 12.0, 20.0, 20.0, 3.0),
])
def test_snr_is_the_linear_radar_equation_to_1e_10_db(range_m, hfov, vfov, pt, nf):
    # 1e-10 dB: a wavelength off by one part in 1e9 moves the SNR by 8.7e-9 dB
    got = snr(range_m, hfov_deg=hfov, vfov_deg=vfov, tx_power_dbm=pt, noise_figure_db=nf)
    assert got == pytest.approx(linear_snr_db(range_m, hfov, vfov, pt, nf), abs=1e-10)


def test_processing_gain_adds_and_system_loss_subtracts():
    other = cfg.replace(RADAR, processing_gain_db=10.0, system_loss_db=3.0)  # 13 dB up
    assert snr(50.0, config=other) == pytest.approx(linear_snr_db(50.0) + 13.0, abs=1e-10)


def test_range_doubling_costs_12_04_db_plus_the_two_way_air():
    no_air = cfg.replace(RADAR, atmospheric_loss_db_per_km=0.0)
    for r in (10.0, 50.0, 100.0):
        assert snr(r, no_air) - snr(2 * r, no_air) == pytest.approx(12.0412, abs=1e-4)
        assert snr(r) - snr(2 * r) == pytest.approx(12.0412 + 2 * 0.4 * r / 1000, abs=1e-4)


def test_the_gain_follows_the_beam():
    gain = lambda h: float(sensors.radar_gain_dbi(sensors.make_params(RADAR, hfov_deg=h), RADAR))  # noqa: E731
    assert gain(30.0) == pytest.approx(10 * math.log10(0.6 * 4 * math.pi / math.radians(30) ** 2 * 2), abs=1e-9)
    assert gain(30.0) - gain(60.0) == pytest.approx(3.0103, abs=1e-4)  # one way
    assert snr(80.0, hfov_deg=30.0) - snr(80.0, hfov_deg=60.0) == pytest.approx(6.0206, abs=1e-4)  # two way
    assert snr(80.0, hfov_deg=30.0) - snr(80.0, hfov_deg=180.0) == pytest.approx(15.563, abs=1e-3)
    grad = jax.jit(jax.grad(lambda h: sensors.radar_gain_dbi(sensors.with_param(RADAR.params, "hfov_deg", h), RADAR)))
    assert float(grad(30.0)) == pytest.approx(-10 / (30.0 * math.log(10)), rel=1e-9)


def test_the_paper_gain_is_the_30_deg_beams_at_any_hfov_and_may_be_the_full_circle():
    paper = sensors.load_config("radar", profile="paper")
    beam_30 = 10 * math.log10(0.6 * 4 * math.pi / (math.radians(30) * math.radians(15)))  # 17.4039 dBi
    for hfov in (30.0, 120.0):
        params = sensors.make_params(paper, hfov_deg=hfov)
        assert float(sensors.radar_gain_dbi(params, paper)) == pytest.approx(beam_30, abs=1e-12)
        assert snr(60.0, paper, hfov_deg=hfov) == pytest.approx(linear_snr_db(60.0, hfov, beam_deg=30.0), abs=1e-10)
    circle = cfg.replace(paper, gain_beam_deg=360.0)  # 12 times the beam: 10 log10(12) = 10.7918 dB less
    assert float(sensors.radar_gain_dbi(circle.params, circle)) == pytest.approx(17.4039 - 10.7918, abs=1e-4)


def test_cross_sections_by_kind():
    rcs = sensors.radar_rcs_dbsm(jnp.asarray([TRUCK, CAR, VAN, CAR]), RADAR)
    np.testing.assert_array_equal(np.asarray(rcs), [20.0, 10.0, 15.0, 10.0])


def test_the_fov_gate_is_half_the_hfov_and_a_margin_of_zero_passes():
    scene = ahead(RADAR, [30.0] * 3, [10.0, 20.0, 40.0])
    hard = {h: np.asarray(jit_p_detect(scene, sensors.make_params(RADAR, hfov_deg=h), RADAR, mode="hard"))[:, 1]
            for h in (30.0, 60.0, 100.0)}
    assert hard[30.0].tolist() == [1, 0, 0] and hard[60.0].tolist() == [1, 1, 0] and hard[100.0].tolist() == [1, 1, 1]
    # A car exactly at the maximum range (55.8 m from the radar) is detected: margin >= 0.
    at_range = sensors.make_params(RADAR, range_m=60.0 - RADAR.mount_x_m)
    scene = make_scene([[0.0, 60.0]], [[0.0, 0.0]])
    assert float(jit_p_detect(scene, at_range, RADAR, mode="hard")[0, 1]) == 1.0
    assert float(jit_p_detect(scene, at_range, RADAR)[0, 1]) == pytest.approx(0.5, abs=0.01)


# At T = 2 the soft gates of the default radar (HFOV 30 deg, range 100 m, threshold 13.2 dB) have
# temperatures 3.2 deg, 3.6 m and 2 dB:
#  car at 100.9 m, 0 deg: FOV margin 15 deg, range margin -0.9 m,
#      SNR 96.858781 - 80.155621 - 0.080720 = 16.622440 dB, margin 3.422440 dB
#  car at 30 m, 16 deg: FOV margin -1 deg, range margin 70 m,
#      SNR 96.858781 - 59.084850 - 0.024 = 37.749931 dB, margin 24.549931 dB
def _hand_p(tau_fov, tau_range, tau_snr):
    return np.array([sigmoid(15 / tau_fov) * sigmoid(-0.9 / tau_range) * sigmoid(3.422440 / tau_snr),
                     sigmoid(-1 / tau_fov) * sigmoid(70 / tau_range) * sigmoid(24.549931 / tau_snr)])


def test_soft_p_at_temperature_2_by_hand():
    p = np.asarray(sensors.radar_p_detect(ahead(RADAR, [100.9, 30.0], [0.0, 16.0]), RADAR.params, RADAR,
                                          temperature=2.0))[:, 1]
    np.testing.assert_allclose(p, _hand_p(3.2, 3.6, 2.0), rtol=2e-6)
    # a gate whose temperature were divided by T (0.8 deg, 0.9 m, 0.5 dB) moves p by > 1e-3
    for wrong in (_hand_p(0.8, 3.6, 2.0), _hand_p(3.2, 0.9, 2.0), _hand_p(3.2, 3.6, 0.5)):
        assert np.max(np.abs(wrong - p)) > 1e-3


@pytest.mark.parametrize("temperature", [2.0, 0.5])
def test_temperature_multiplies_every_soft_temperature_occlusion_included(temperature):
    # An occluder 38 m ahead of the radar, 1.6 m to the left (two near-temperatures nearer than the
    # car 40 m ahead); the SNR gate carries the soft occlusion and moves by > 0.1 dB.
    scene = make_scene([[0.0, RADAR.mount_x_m + 38.0, RADAR.mount_x_m + 40.0]], [[0.0, 1.6, 0.0]])
    assert_temperature_scales_the_config(_radar_terms, Tracks.of(scene), RADAR, temperature, gate=2, vehicle=2,
                                         least=0.1)


def test_a_covered_fraction_costs_15_db_and_a_hidden_car_is_still_seen():
    # SNR - threshold = SNR(40 m) - 15 dB * covered - 13.2 dB, SNR(40 m) = 96.8588 - 40 log10(40) - 0.032.
    margin = np.asarray(terms(occlusion_scene(RADAR.mount_x_m), RADAR.params, RADAR, "hard")[0][2][0])[2]
    np.testing.assert_allclose(margin, 32.7447 - 15.0 * np.array(COVERED) - 13.2, atol=1e-3)
    # A car right behind a truck 20 m ahead is wholly shadowed: the full 15 dB, and still detected.
    scene = make_scene([[0.0, 20.0, 40.0, 40.0, 0.0]], [[0.0, 0.0, 0.0, 3.7, 0.0]],
                       length_m=[4.5, 12.0, 4.5, 4.5, 4.5], width_m=[1.8, 2.5, 1.8, 1.8, 1.8],
                       kind=[CAR, TRUCK, CAR, CAR, CAR], present=[True] * 4 + [False])
    margin = float(terms(scene, RADAR.params, RADAR, "hard")[0][2][0][2, 0])
    assert margin + 13.2 == pytest.approx(snr(40.0 - RADAR.mount_x_m) - 15.0, abs=1e-9)
    assert np.asarray(jit_p_detect(scene, RADAR.params, RADAR, mode="hard"))[0].tolist() == [1, 1, 1, 1, 0]


def test_rain_lowers_the_snr_margin_by_its_two_way_loss():
    # ITU-R P.838-3 at 77 GHz, 25 mm/h: 10.99 (V) to 11.41 (H) dB/km, 2.20 to 2.28 dB over 2 x 100 m.
    rain = sensors.Weather(rain_mm_h=25.0)
    clear, rainy = (float(terms(ahead(RADAR, [100.0]), RADAR.params, RADAR, "soft", w)[0][2][0][1, 0])
                    for w in (sensors.CLEAR, rain))
    assert clear - rainy == pytest.approx(float(rain.radar_loss_db(np.float64(100.0))), rel=1e-9)
    assert 2.19 < clear - rainy < 2.29


# Noise: sqrt(accuracy^2 + (resolution 10^(-SNR/20) / sqrt 2)^2) (Table I: accuracy 0.4 m and
# 0.1 deg, resolution 1.8 m and 1.6 deg), the SNR clipped to [-100, 100] dB:
#   20 m, SNR 44.80 dB: thermal 10^(-2.240) / sqrt 2 = 0.004077 -> 0.400067 m, 0.100212 deg
#  200 m, SNR 4.658 dB: thermal 10^(-0.2329) / sqrt 2 = 0.41352 -> 0.845172 m, 0.669311 deg
@pytest.mark.parametrize("range_m, sigma_r, sigma_az_deg", [(20.0, 0.400067, 0.100212), (200.0, 0.845172, 0.669311)])
def test_noise_scales_by_hand(range_m, sigma_r, sigma_az_deg):
    _, _, _, range_sigma, azimuth_sigma = terms(ahead(RADAR, [range_m]), RADAR.params, RADAR)
    assert float(range_sigma[1, 0]) == pytest.approx(sigma_r, rel=1e-5)
    assert float(azimuth_sigma[1, 0]) == pytest.approx(math.radians(sigma_az_deg), rel=1e-5)


def test_the_thermal_noise_is_clipped_at_plus_and_minus_100_db():
    # Swerling law, a car beside the radar (90 deg) 20 m away: the Gaussian beam's two-way loss is
    # 2 * 12.0412 * (90 / 30)^2 = 216.74 dB, SNR ~ -171.9 dB: thermal = 10^5 / sqrt 2.
    # A car 0.5 m ahead: SNR 108.90 dB, thermal = 10^-5 / sqrt 2 (unclipped sigma_R would be 0.4 + 2.7e-11).
    for config, scene, thermal, rel in ((SWERLING, ahead(RADAR, [20.0], [90.0]), 1e5, 1e-9),
                                        (RADAR, ahead(RADAR, [0.5]), 1e-5, 1e-13)):
        _, _, _, range_sigma, azimuth_sigma = terms(scene, config.params, config)
        thermal /= math.sqrt(2.0)
        assert float(range_sigma[1, 0]) == pytest.approx(math.hypot(0.4, 1.8 * thermal), rel=rel, abs=0)
        assert float(azimuth_sigma[1, 0]) == pytest.approx(math.radians(math.hypot(0.1, 1.6 * thermal)), rel=rel, abs=0)
