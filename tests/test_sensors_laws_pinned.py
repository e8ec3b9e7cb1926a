"""The probabilistic detection laws (`diffsense/sensors/_laws.py`) at their floors, clips and
input bounds, against hand values: the edges that a sensor-level test rarely reaches.

Numbers: Phi(1) = 0.8413447460685429, Phi(0.9486833) = 0.8286050 (erfc, below); the Gaussian
beam's loss constant 10 log10(e) * 4 ln 2 = 4.3429448 * 2.7725887 = 12.0411998 dB.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.runtime._errors import InputError
from diffsense.sensors._laws import (
    CameraDetection,
    RadarDetection,
    confidence_mean,
    gaussian_beam_loss_db,
    in_fov_fraction,
    log_reported_below,
)


def _phi(z):
    return 0.5 * math.erfc(-z / math.sqrt(2.0))


@pytest.mark.parametrize("gap_m, sigma_m, z", [
    (1e-3, 0.0, 1.0),                    # no noise: the 1 mm floor alone
    (3e-3, 3e-3, 3 / math.sqrt(10.0)),   # sqrt(3^2 + 1^2) mm = 3.1623 mm
    (-2.0, 1.0, -2.0 / math.sqrt(1.0 + 1e-6)),
])
def test_range_cut_noise_has_a_1_mm_floor_in_quadrature(gap_m, sigma_m, z):
    got = float(log_reported_below(jnp.asarray(100.0), jnp.asarray(100.0 - gap_m), jnp.asarray(sigma_m)))
    assert math.exp(got) == pytest.approx(_phi(z), rel=1e-9)


def test_gaussian_beam_width_is_floored_at_1e_6_deg():
    # HFOV 0 (or below): the beam is 1e-6 deg = 1.7453293e-8 rad wide; at 1e-9 rad off boresight
    # the loss is 12.0412 * (1e-9 / 1.7453293e-8)^2 = 12.0412 * 0.0032828 = 0.0395290 dB.
    for hfov in (0.0, -5.0, 1e-6):
        loss = float(gaussian_beam_loss_db(jnp.asarray(1e-9), jnp.asarray(hfov)))
        assert loss == pytest.approx(12.0411998 * (1e-9 / 1.7453293e-8) ** 2, rel=1e-6)
    # a beam 2e-6 deg wide is not floored: a quarter of that loss
    loss = float(gaussian_beam_loss_db(jnp.asarray(1e-9), jnp.asarray(2e-6)))
    assert loss == pytest.approx(0.25 * 12.0411998 * (1e-9 / 1.7453293e-8) ** 2, rel=1e-6)


def test_in_fov_fraction_left_edge_wide_vehicle_and_zero_width_on_the_edge():
    edge = math.radians(15.0)  # HFOV 30 deg
    az = jnp.asarray([-edge - math.radians(0.5), 0.0, edge, -edge, edge + 1e-9])
    half = jnp.asarray([math.radians(1.0), math.radians(20.0), 0.0, 0.0, 0.0])
    got = np.asarray(in_fov_fraction(az, half, 30.0))
    # left edge: [-16.5, -14.5] deg has 0.5 of 2 deg inside; a 40 deg wide vehicle centred shows
    # the image's 30 deg of it; zero width exactly on either edge counts as inside, just past: out
    np.testing.assert_allclose(got, [0.25, 0.75, 1.0, 1.0, 0.0], atol=1e-12)


def test_in_fov_fraction_of_small_far_vehicles_never_exceeds_1_in_float32():
    # 0.2 mrad wide vehicles well inside the image: in float32, (az + half) - (az - half) rounds
    # up to 1.7e-5 past the width for 39 of these 101 azimuths; a fraction stays <= 1
    az = jnp.linspace(0.1, 0.5, 101, dtype=jnp.float32)
    got = np.asarray(in_fov_fraction(az, jnp.full_like(az, 1e-4), 120.0))
    assert got.dtype == np.float32 and got.max() <= 1.0 and got.min() > 0.9998


def test_confidence_mean_clips_the_visible_fraction_to_0_1():
    # width 14 px: size = sigmoid((14 - 10) / 2) = sigmoid(2) = 0.8807971; mean = 0.95 * size * v
    kw = dict(confidence_max=0.95, width50_px=10.0, width_scale_px=2.0)
    got = np.asarray(confidence_mean(jnp.asarray([14.0, 14.0, 14.0, 10.0]),
                                     jnp.asarray([1.5, -0.5, 0.5, 1.0]), **kw))
    np.testing.assert_allclose(got, [0.95 * 0.8807971, 0.0, 0.95 * 0.8807971 * 0.5, 0.475], rtol=1e-7)


@pytest.mark.parametrize("pfa", [1e-300, 0.5, 1.0 - 1e-16])
def test_radar_pfa_inside_0_1_is_accepted(pfa):
    assert RadarDetection(law="swerling1", pfa=pfa).pfa == pfa


@pytest.mark.parametrize("pfa", [0.0, 1.0, -1e-6, 1.5])
def test_radar_pfa_outside_0_1_is_refused(pfa):
    with pytest.raises(InputError, match=r"^radar detection pfa must be in \(0, 1\), got "):
        RadarDetection(law="swerling1", pfa=pfa)


@pytest.mark.parametrize("changes", [
    dict(confidence_max=1.0), dict(confidence_max=1e-9), dict(threshold=0.0), dict(threshold=1.0),
    dict(width_scale_px=1e-9), dict(sigma=1e-9),
])
def test_camera_law_bounds_are_accepted(changes):
    law = CameraDetection(law="confidence", **changes)
    assert all(getattr(law, k) == v for k, v in changes.items())


@pytest.mark.parametrize("changes, field", [
    (dict(confidence_max=0.0), "confidence_max"), (dict(confidence_max=1.0 + 1e-9), "confidence_max"),
    (dict(threshold=-1e-9), "threshold"), (dict(threshold=1.0 + 1e-9), "threshold"),
    (dict(width_scale_px=0.0), "width_scale_px"), (dict(sigma=0.0), "sigma"),
    (dict(width_scale_px=-1.0), "width_scale_px"), (dict(sigma=-1.0), "sigma"),
])
def test_camera_law_out_of_bounds_is_refused(changes, field):
    # the message names the field and its bounds, from its first word
    with pytest.raises(InputError, match=rf"^camera detection [a-z_ ]*{field}[a-z_ ]* must be "):
        CameraDetection(law="confidence", **changes)
