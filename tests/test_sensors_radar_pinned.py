"""The radar (`diffsense/sensors/_radar.py`) pinned where its mutation run found the tests blind.

Expected values are hand calculations (written out in the comments, from the constants of
configs/sensors/radar.toml and the paper's Table I) or float64 recomputations written
differently from the model (the radar equation in linear power, not in decibels). The
temperature is checked as a documented property: a temperature T acts as every soft-gate
temperature of the config multiplied by T, occlusion's included.
"""

from __future__ import annotations

import math

import jax
import numpy as np
import pytest
from _sensor_temperature import assert_temperature_scales_the_config
from test_sensor_scenes import make_scene

from diffsense import config as cfg
from diffsense import sensors as sensor
from diffsense.sensors._geometry import Tracks
from diffsense.sensors._laws import RadarDetection
from diffsense.sensors._radar import _radar_terms

RADAR = sensor.load_config("radar")
SWERLING = cfg.replace(RADAR, detection=RadarDetection(law="swerling1"))
MOUNT = RADAR.mount_x_m  # 4.2 m


def _sigmoid(z):
    return 1.0 / (1.0 + math.exp(-z))


def _terms(config, scene, temperature=1.0, mode="soft", params=None):
    return _radar_terms(Tracks.of(scene), params or config.params, config, mode, temperature)


def _cars(ranges_m, azimuths_deg):
    """One frame per car: the ego at the origin and one car at (range, azimuth) from the radar."""
    az = np.radians(azimuths_deg)
    r = np.asarray(ranges_m, float)
    x = np.stack([np.zeros(len(r)), MOUNT + r * np.cos(az)], axis=1)
    y = np.stack([np.zeros(len(r)), r * np.sin(az)], axis=1)
    return make_scene(x, y)


# --- the temperature ------------------------------------------------------------------------
# At T = 2 the soft gates of the default radar (HFOV 30 deg, range 100 m, threshold 13.2 dB) have
# temperatures 3.2 deg, 3.6 m and 2 dB. SNR = 96.858781 - 40 log10(R) - 0.0008 R dB on boresight
# (the hand link budget of tests/test_physics_pinned.py):
#  car at 100.9 m, 0 deg: FOV margin 15 deg, range margin -0.9 m,
#      SNR 96.858781 - 80.155621 - 0.080720 = 16.622440 dB, margin 3.422440 dB
#  car at 30 m, 16 deg: FOV margin -1 deg, range margin 70 m,
#      SNR 96.858781 - 59.084850 - 0.024 = 37.749931 dB, margin 24.549931 dB
def _hand_p(tau_fov, tau_range, tau_snr):
    return np.array([
        _sigmoid(15 / tau_fov) * _sigmoid(-0.9 / tau_range) * _sigmoid(3.422440 / tau_snr),
        _sigmoid(-1 / tau_fov) * _sigmoid(70 / tau_range) * _sigmoid(24.549931 / tau_snr),
    ])


def test_soft_p_at_temperature_2_by_hand():
    scene = _cars([100.9, 30.0], [0.0, 16.0])
    p = np.asarray(sensor.radar_p_detect(scene, RADAR.params, RADAR, temperature=2.0))[:, 1]
    np.testing.assert_allclose(p, _hand_p(3.2, 3.6, 2.0), rtol=2e-6)
    # a gate whose temperature were divided by T (0.8 deg, 0.9 m, 0.5 dB) moves p by > 1e-3
    for wrong in (_hand_p(0.8, 3.6, 2.0), _hand_p(3.2, 0.9, 2.0), _hand_p(3.2, 3.6, 0.5)):
        assert np.max(np.abs(wrong - p)) > 1e-3


def _occluded():
    """Ego; an occluder 38 m ahead of the radar, 1.6 m to the left; a car 40 m ahead: the
    occluder is 2 m (two near-temperatures at T = 1) nearer and covers part of the car, its
    interval edge within a few overlap temperatures of the car's centre."""
    return make_scene([[0.0, MOUNT + 38.0, MOUNT + 40.0]], [[0.0, 1.6, 0.0]])


@pytest.mark.parametrize("temperature", [2.0, 0.5])
def test_temperature_multiplies_every_soft_temperature_occlusion_included(temperature):
    # gate 2 carries the soft occlusion; it moves by > 0.1 between temperatures 2 and 1/2
    assert_temperature_scales_the_config(_radar_terms, RADAR, _occluded(), temperature, gate=2, vehicle=2,
                                         least=0.1)


# --- the SNR clip of the thermal noise term -------------------------------------------------
# thermal = 10^(-clip(SNR, -100, 100) / 20) / sqrt 2; sigma = hypot(accuracy, resolution * thermal)
# (Table I: 0.4 m / 0.1 deg accuracy, 1.8 m / 1.6 deg resolution).
def test_thermal_noise_is_clipped_at_minus_100_db():
    # Swerling law, a car beside the radar (90 deg) 20 m away: the Gaussian beam's two-way loss
    # is 2 * 12.0412 * (90 / 30)^2 = 216.74 dB, so SNR ~ 44.80 - 216.74 = -171.9 dB < -100 dB:
    # thermal = 10^5 / sqrt 2 = 70710.678 -> sigma 127279.22 m and 113137.085 deg.
    terms = _terms(SWERLING, _cars([20.0], [90.0]))
    thermal = 1e5 / math.sqrt(2.0)
    assert float(terms[3][1, 0]) == pytest.approx(math.hypot(0.4, 1.8 * thermal), rel=1e-9)
    assert float(terms[4][1, 0]) == pytest.approx(math.radians(math.hypot(0.1, 1.6 * thermal)), rel=1e-9)


def test_thermal_noise_is_clipped_at_plus_100_db():
    # A car 0.5 m ahead: SNR 108.90 dB > 100 dB, so thermal = 10^-5 / sqrt 2 and
    # sigma_R = hypot(0.4, 1.8e-5 / sqrt 2) = 0.4 + 2.025e-10 m (unclipped: 0.4 + 2.7e-11).
    terms = _terms(RADAR, _cars([0.5], [0.0]))
    thermal = 1e-5 / math.sqrt(2.0)
    assert float(terms[3][1, 0]) == pytest.approx(math.hypot(0.4, 1.8 * thermal), rel=1e-13, abs=0)
    assert float(terms[4][1, 0]) == pytest.approx(math.radians(math.hypot(0.1, 1.6 * thermal)),
                                                  rel=1e-13, abs=0)


# --- the radar equation to float64 precision ------------------------------------------------
def _linear_snr_db(range_m, hfov_deg=30.0, vfov_deg=15.0, rcs_m2=10.0, pt_dbm=14.0, nf_db=4.8,
                   beam_deg=None):
    """The radar equation in linear power (W), with the model's rounded kT0 of -174 dBm/Hz."""
    lam = 299792458.0 / 77e9
    beam = beam_deg if beam_deg is not None else hfov_deg
    gain = 0.6 * 4 * math.pi / (math.radians(beam) * math.radians(vfov_deg))
    received = 10 ** (pt_dbm / 10) * 1e-3 * gain**2 * lam**2 * rcs_m2 / ((4 * math.pi) ** 3 * range_m**4)
    noise = 10 ** (-174 / 10) * 1e-3 * 25e3 * 10 ** (nf_db / 10)
    loss = 10 ** ((6.0 + 2 * 0.4 * range_m / 1000) / 10)
    return 10 * math.log10(received / noise / loss)


@pytest.mark.parametrize("range_m, hfov, vfov, pt, nf", [
    (20.0, 30.0, 15.0, 14.0, 4.8), (73.0, 90.0, 10.0, 10.0, 6.0), (150.0, 12.0, 20.0, 20.0, 3.0),
])
def test_snr_matches_the_linear_radar_equation_to_1e_10_db(range_m, hfov, vfov, pt, nf):
    # 1e-10 dB: a wavelength off by one part in 1e9 moves the SNR by 8.7e-9 dB
    params = sensor.make_params(RADAR, hfov_deg=hfov, vfov_deg=vfov, tx_power_dbm=pt, noise_figure_db=nf)
    got = float(sensor.radar_snr_db(jax.numpy.asarray(range_m), 10.0, params, RADAR))
    assert got == pytest.approx(_linear_snr_db(range_m, hfov, vfov, 10.0, pt, nf), abs=1e-10)


def test_processing_gain_adds_and_system_loss_subtracts():
    # The shipped radar has no processing gain (0 dB: it is inside the 25 kHz bandwidth); a
    # radar with 10 dB of integration gain and 3 dB of system loss (instead of 6) is 13 dB up.
    other = cfg.replace(RADAR, processing_gain_db=10.0, system_loss_db=3.0)
    got = float(sensor.radar_snr_db(jax.numpy.asarray(50.0), 10.0, other.params, other))
    assert got == pytest.approx(_linear_snr_db(50.0) + 13.0, abs=1e-10)


def test_paper_profile_gain_is_the_30_deg_beam_at_any_hfov():
    # The paper's radar: 100 m at every HFOV, its gain that of a 30 x 15 deg beam (17.4039 dBi).
    paper = sensor.load_config("radar", profile="paper")
    for hfov in (30.0, 120.0):
        params = sensor.make_params(paper, hfov_deg=hfov)
        assert float(sensor.radar_gain_dbi(params, paper)) == pytest.approx(
            10 * math.log10(0.6 * 4 * math.pi / (math.radians(30) * math.radians(15))), abs=1e-12)
        got = float(sensor.radar_snr_db(jax.numpy.asarray(60.0), 10.0, params, paper))
        assert got == pytest.approx(_linear_snr_db(60.0, hfov, beam_deg=30.0), abs=1e-10)
