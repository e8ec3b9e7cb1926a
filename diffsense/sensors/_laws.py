"""Detection as a physical probability: the physical profile's laws, and the threshold gates they replace.

A sensor's `[detection] law` (its TOML) picks how a detection happens:

- "threshold" (the paper profile's): deterministic thresholds (FOV, range, SNR or visible
  fraction), relaxed by logistic gates in soft mode (`_gates.py`).
- radar "swerling1" (the physical profile's): a Swerling I target (exponentially distributed echo power, one look)
  in complex Gaussian noise, square-law detected against the threshold that gives the
  false-alarm probability Pfa: Pd = Pfa^(1 / (1 + SNR)), SNR linear. The azimuth edge is the
  antenna pattern (`gaussian_beam_loss_db`), and the range cut is made on the measured range.
- camera "confidence" (the physical profile's): the detector's confidence has a mean that grows with the object's width
  in pixels and its visible fraction (`confidence_mean`), plus frame-to-frame Gaussian noise;
  a detection is confidence >= the threshold (the paper's 0.6), so
  p = Phi((mean - threshold) / sigma).

Under these laws p is the probability of the physical detection event itself: "soft" and
"hard" mode give the same law, and differ only in the occlusion geometry (soft nearer/overlap
in soft mode, exact in hard mode). Everything is formed as a log-probability (sums, `log_ndtr`,
`log Pd = log Pfa / (1 + SNR)`), so no product of small numbers and no overflow occurs at any
parameter's extreme.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Literal

import jax
import jax.numpy as jnp
from jax.scipy.special import log_ndtr
from jaxtyping import Array, Float

from diffsense.runtime import InputError

RadarLaw = Literal["threshold", "swerling1"]
CameraLaw = Literal["threshold", "confidence"]

# 10 log10(e) * 4 ln 2: the one-way loss [dB] of a Gaussian beam at theta = its -3 dB width.
_GAUSS_BEAM_DB = 10.0 * math.log10(math.e) * 4.0 * math.log(2.0)
# The smallest beam width [deg] the pattern divides by: far below any real antenna, keeps the
# division finite for a traced HFOV at 0 (outside the domain, but a solver may probe near it).
_MIN_BEAM_DEG = 1e-6
# A floor on the range-cut noise [m] (1 mm): a camera's depth noise vanishes at zero range.
_MIN_RANGE_SIGMA_M = 1e-3


@dataclasses.dataclass(frozen=True)
class RadarDetection:
    """The radar's detection law (the `[detection]` table of its TOML); static.

    Attributes:
        law: "threshold" (deterministic gates) or "swerling1" (module docstring).
        pfa: false-alarm probability per cell and look of the "swerling1" law [-].
    """

    law: RadarLaw = "swerling1"
    pfa: float = 1e-6

    def __post_init__(self):
        _require(0.0 < self.pfa < 1.0, f"radar detection pfa must be in (0, 1), got {self.pfa:g}")


@dataclasses.dataclass(frozen=True)
class CameraDetection:
    """The camera's detection law (the `[detection]` table of its TOML); static.

    Attributes:
        law: "threshold" (deterministic gates) or "confidence" (module docstring).
        confidence_max: mean confidence of a large, fully visible object [-].
        width50_px: object width at which the mean confidence is half its maximum [px].
        width_scale_px: scale of the logistic in width [px].
        sigma: frame-to-frame standard deviation of the confidence [-].
        threshold: a detection is confidence >= this [-].
    """

    law: CameraLaw = "confidence"
    confidence_max: float = 0.95
    width50_px: float = 10.0
    width_scale_px: float = 2.0
    sigma: float = 0.1
    threshold: float = 0.6

    def __post_init__(self):
        _require(0.0 < self.confidence_max <= 1.0, "camera detection confidence_max must be in (0, 1]")
        _require(0.0 <= self.threshold <= 1.0, "camera detection threshold must be in [0, 1]")
        _require(self.width_scale_px > 0.0 and self.sigma > 0.0,
                 "camera detection width_scale_px and sigma must be > 0")


def _require(ok: bool, message: str) -> None:
    if not ok:
        raise InputError(message)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class LogProbability:
    """A sensor's detection probability given as its log [V, T] (what a probabilistic law
    returns where the threshold law returns its gates)."""

    log_p: Float[Array, "V T"]


def swerling1_log_pd(snr_db: Float[Array, "*S"], pfa: float) -> Float[Array, "*S"]:
    """log Pd of a Swerling I target at `snr_db` [dB] for false-alarm probability `pfa`.

    Pd = Pfa^(1 / (1 + SNR)), so log Pd = log Pfa * sigmoid(-ln SNR): the sigmoid form is exact
    and neither overflows at +300 dB nor loses the gradient at -300 dB.
    """
    ln_snr = snr_db * (math.log(10.0) / 10.0)
    return math.log(pfa) * jax.nn.sigmoid(-ln_snr)


def gaussian_beam_loss_db(azimuth_rad: Float[Array, "*S"], hfov_deg) -> Float[Array, "*S"]:
    """One-way gain loss [dB] of a Gaussian beam whose -3 dB full width is `hfov_deg`.

    G(theta) = G0 exp(-4 ln2 (theta / HFOV)^2): 3.01 dB down at theta = HFOV / 2, 12.04 dB at
    theta = HFOV, falling smoothly on past the edge (no hard gate). The radar equation takes
    it twice (transmit and receive).
    """
    beam_rad = jnp.deg2rad(jnp.maximum(hfov_deg, _MIN_BEAM_DEG))
    return _GAUSS_BEAM_DB * (azimuth_rad / beam_rad) ** 2


def log_reported_below(limit_m, range_m, sigma_m) -> Float[Array, "*S"]:
    """log P(measured range <= limit): the range is measured with Gaussian noise of `sigma_m`
    [m] and the sensor reports targets out to `limit_m` [m] only."""
    sigma = jnp.sqrt(sigma_m**2 + _MIN_RANGE_SIGMA_M**2)
    return log_ndtr((limit_m - range_m) / sigma)


def confidence_mean(width_px, visible_fraction, *, confidence_max: float, width50_px: float,
                    width_scale_px: float) -> Float[Array, "*S"]:
    """The detector's mean confidence [-] for an object `width_px` wide in the image with
    `visible_fraction` of it unhidden.

    Assumptions (stated, not fitted): a fully visible object's confidence rises with its width
    in pixels as a logistic, half its maximum at `width50_px` with slope scale `width_scale_px`,
    up to `confidence_max`; hiding part of it removes evidence in proportion, so the mean is
    scaled by the visible fraction.
    """
    size = jax.nn.sigmoid((width_px - width50_px) / width_scale_px)
    return confidence_max * size * jnp.clip(visible_fraction, 0.0, 1.0)


def log_confidence_above(mean, threshold: float, sigma: float) -> Float[Array, "*S"]:
    """log P(mean + sigma Z >= threshold), Z standard normal: the detection under
    frame-to-frame confidence noise."""
    return log_ndtr((mean - threshold) / sigma)


def in_fov_fraction(azimuth_rad, half_width_rad, hfov_deg) -> Float[Array, "*S"]:
    """Fraction [-] of a vehicle's angular interval [az - half, az + half] inside the image
    [-HFOV/2, HFOV/2]: a vehicle on the image's edge is seen truncated, not all or nothing.
    A vehicle of zero width is inside or outside (its centre decides)."""
    edge = 0.5 * jnp.deg2rad(hfov_deg)
    lo = jnp.maximum(azimuth_rad - half_width_rad, -edge)
    hi = jnp.minimum(azimuth_rad + half_width_rad, edge)
    width = 2.0 * half_width_rad
    ok = width > 0
    frac = jnp.clip(hi - lo, 0.0, None) / jnp.where(ok, width, 1.0)
    centre = (jnp.abs(azimuth_rad) <= edge).astype(frac.dtype)
    return jnp.where(ok, jnp.minimum(frac, 1.0), centre)
