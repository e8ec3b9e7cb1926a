"""Weather physics for the sensors: rain attenuation of the 77 GHz radar, fog and rain for the camera.

Pure, differentiable JAX functions (float32 or float64, whatever the inputs are); clear weather
(rain 0 mm/h, visibility +inf) gives exactly zero loss, so a sensor model that applies them is
unchanged bit for bit when there is no weather.

Radar: rain (Recommendation ITU-R P.838-3, "Specific attenuation model for rain for use in
prediction methods", 2005). The specific attenuation is the power law gamma = k R^alpha [dB/km]
in the rain rate R [mm/h]; k and alpha follow from the frequency f [GHz] by the recommendation's
regressions (its equations 2 and 3, coefficients in its Tables 1-4, transcribed below):

    log10 k = sum_j a_j exp(-((log10 f - b_j) / c_j)^2) + m_k log10 f + c_k     (j = 1..4)
    alpha   = sum_j a_j exp(-((log10 f - b_j) / c_j)^2) + m_a log10 f + c_a     (j = 1..5)

for horizontal (H) and vertical (V) polarisation, combined for a path of elevation theta and a
polarisation tilt tau (0 = horizontal, pi/2 = vertical) by its equations 4 and 5. At 77 GHz they
give k_H = 1.1320, alpha_H = 0.7177, k_V = 1.1276, alpha_V = 0.7073, so gamma_H = 5.91, 11.41,
18.76 and 30.85 dB/km (gamma_V = 5.75, 10.99, 17.94 and 29.29 dB/km) at 10, 25, 50 and 100 mm/h
(tests/test_weather.py pins them). A radar echo
crosses the rain twice: the two-way loss at range r is 2 gamma r / 1000 [dB]. The one-sided
derivative of R^alpha at R = 0 is infinite (alpha < 1); the functions report 0 there (a safe
`where`), and a finite derivative at every R > 0. Fog barely attenuates 77 GHz and is not
modelled for the radar.

Camera: contrast (Koschmieder's law). Fog of meteorological visibility V [m] has the extinction
coefficient beta = -ln(0.02) / V = 3.912 / V [1/m] (visibility is where the contrast of a black
object against the horizon sky falls to 2 %), and an object of intrinsic contrast C0 seen through
range r has the apparent contrast C(r) = C0 exp(-beta r). Assumption: the camera resolves a
vehicle while its apparent contrast is at least the threshold eps (2 %, the same as in the
definition of visibility), i.e. out to the contrast range r_c = ln(C0 / eps) / beta, which equals
V for C0 = 1; `contrast_transmission` = C(r) / C0 is the factor by which the image contrast,
and with it a detector's confidence, falls. Wire the camera's range limit as
`jnp.minimum(range_m, contrast_range_m(...))`: r_c is +inf in clear weather, so the minimum is
the clear-weather range exactly, and its derivative is finite (the safe `where` below).

Rain for the camera: rain lowers the visibility. Assumption: its optical extinction follows
Carbonneau's power law for free-space optical links in rain, 1.076 R^0.67 [dB/km] (measured in
the near infrared; raindrops are millimetres across, far larger than any optical wavelength, so
their extinction is the same in the visible). In nepers per metre that is
beta_rain = 1.076 R^0.67 / (10 log10 e) / 1000 [1/m], and extinctions add:
beta = 3.912 / V + beta_rain (`camera_extinction_1pm`): 25 mm/h alone gives a visibility of
1827 m. Drops on the lens or windscreen and spray are not modelled.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

RADAR_FREQUENCY_GHZ = 77.0  # Table I of the paper
KOSCHMIEDER_THRESHOLD = 0.02  # contrast threshold of meteorological visibility
KOSCHMIEDER_CONSTANT = -math.log(KOSCHMIEDER_THRESHOLD)  # 3.912 = -ln(0.02)
_DB_PER_NEPER = 10.0 * math.log10(math.e)  # 4.343 dB of power per neper
# Carbonneau's optical rain attenuation, 1.076 R^0.67 dB/km (R in mm/h).
_OPTICAL_RAIN_K = 1.076
_OPTICAL_RAIN_ALPHA = 0.67

# ITU-R P.838-3, Tables 1-4: rows (a_j, b_j, c_j), then (m, c).
_K_H = (((-5.33980, -0.10008, 1.13098), (-0.35351, 1.26970, 0.45400),
         (-0.23789, 0.86036, 0.15354), (-0.94158, 0.64552, 0.16817)), (-0.18961, 0.71147))
_K_V = (((-3.80595, 0.56934, 0.81061), (-3.44965, -0.22911, 0.51059),
         (-0.39902, 0.73042, 0.11899), (0.50167, 1.07319, 0.27195)), (-0.16398, 0.63297))
_ALPHA_H = (((-0.14318, 1.82442, -0.55187), (0.29591, 0.77564, 0.19822),
             (0.32177, 0.63773, 0.13164), (-5.37610, -0.96230, 1.47828),
             (16.1721, -3.29980, 3.43990)), (0.67849, -1.95537))
_ALPHA_V = (((-0.07771, 2.33840, -0.76284), (0.56727, 0.95545, 0.54039),
             (-0.20238, 1.14520, 0.26809), (-48.2991, 0.791669, 0.116226),
             (48.5833, 0.791459, 0.116479)), (-0.053739, 0.83433))


def _float(x: ArrayLike) -> Array:
    x = jnp.asarray(x)
    return x if jnp.issubdtype(x.dtype, jnp.floating) else x.astype(jnp.result_type(float))


def _regression(table, log_f: Array) -> Array:
    """The P.838-3 Gaussian-sum regression at log10 f (equations 2 and 3, without the 10^)."""
    rows, (m, c) = table
    total = m * log_f + c
    for a, b, width in rows:
        total = total + a * jnp.exp(-(((log_f - b) / width) ** 2))
    return total


def rain_coefficients(
    frequency_ghz: Float[ArrayLike, "*S"] = RADAR_FREQUENCY_GHZ,
    tilt_rad: Float[ArrayLike, "*S"] = 0.0,
    elevation_rad: Float[ArrayLike, "*S"] = 0.0,
) -> tuple[Float[Array, "*S"], Float[Array, "*S"]]:
    """ITU-R P.838-3 (k [dB/km/(mm/h)^alpha], alpha [-]) at f in 1-1000 GHz.

    `tilt_rad` is the polarisation tilt from horizontal (0 = H, pi/2 = V, pi/4 = circular) and
    `elevation_rad` the path elevation (0 for a radar looking along the road).
    """
    log_f = jnp.log10(_float(frequency_ghz))
    k_h, k_v = 10.0 ** _regression(_K_H, log_f), 10.0 ** _regression(_K_V, log_f)
    a_h, a_v = _regression(_ALPHA_H, log_f), _regression(_ALPHA_V, log_f)
    mix = jnp.cos(elevation_rad) ** 2 * jnp.cos(2.0 * tilt_rad)
    k = 0.5 * (k_h + k_v + (k_h - k_v) * mix)
    alpha = 0.5 * (k_h * a_h + k_v * a_v + (k_h * a_h - k_v * a_v) * mix) / k
    return k, alpha


def _power_law(rate: Array, k, alpha) -> Array:
    """k rate^alpha, exactly 0 at rate <= 0 with a finite (zero) derivative there."""
    wet = rate > 0.0
    safe = jnp.where(wet, rate, 1.0)  # keeps the unused branch's derivative finite
    return jnp.where(wet, k * safe**alpha, 0.0)


def rain_specific_attenuation_db_per_km(
    rain_mm_per_h: Float[ArrayLike, "*S"],
    frequency_ghz: Float[ArrayLike, "*S"] = RADAR_FREQUENCY_GHZ,
    tilt_rad: Float[ArrayLike, "*S"] = 0.0,
    elevation_rad: Float[ArrayLike, "*S"] = 0.0,
) -> Float[Array, "*S"]:
    """One-way specific attenuation of rain gamma = k R^alpha [dB/km] (ITU-R P.838-3); 0 at R = 0."""
    rate = _float(rain_mm_per_h)
    # Python-number defaults take the rain rate's precision (float32 stays float32 under x64).
    dtype = jnp.result_type(rate, frequency_ghz, tilt_rad, elevation_rad)
    k, alpha = rain_coefficients(*(jnp.asarray(x, dtype) for x in (frequency_ghz, tilt_rad, elevation_rad)))
    return _power_law(rate.astype(dtype), k, alpha)


def rain_two_way_loss_db(
    range_m: Float[ArrayLike, "*S"],
    rain_mm_per_h: Float[ArrayLike, "*S"],
    frequency_ghz: Float[ArrayLike, "*S"] = RADAR_FREQUENCY_GHZ,
    tilt_rad: Float[ArrayLike, "*S"] = 0.0,
    elevation_rad: Float[ArrayLike, "*S"] = 0.0,
) -> Float[Array, "*S"]:
    """Two-way rain loss of a radar echo from range r: 2 gamma r / 1000 [dB]; exactly 0 without rain."""
    gamma = rain_specific_attenuation_db_per_km(rain_mm_per_h, frequency_ghz, tilt_rad, elevation_rad)
    return 2.0 * gamma * _float(range_m) / 1000.0


def fog_extinction_1pm(visibility_m: Float[ArrayLike, "*S"]) -> Float[Array, "*S"]:
    """Koschmieder extinction coefficient beta = 3.912 / V [1/m]; exactly 0 at V = +inf."""
    return KOSCHMIEDER_CONSTANT / _float(visibility_m)


def rain_extinction_1pm(rain_mm_per_h: Float[ArrayLike, "*S"]) -> Float[Array, "*S"]:
    """Optical extinction coefficient of rain, 1.076 R^0.67 dB/km in nepers per metre [1/m]."""
    db_per_km = _power_law(_float(rain_mm_per_h), _OPTICAL_RAIN_K, _OPTICAL_RAIN_ALPHA)
    return db_per_km / (_DB_PER_NEPER * 1000.0)


def camera_extinction_1pm(
    visibility_m: Float[ArrayLike, "*S"], rain_mm_per_h: Float[ArrayLike, "*S"] = 0.0
) -> Float[Array, "*S"]:
    """Total optical extinction of fog (visibility V) and rain (rate R) [1/m]; 0 in clear weather."""
    return fog_extinction_1pm(visibility_m) + rain_extinction_1pm(rain_mm_per_h)


def visibility_m(extinction_1pm: Float[ArrayLike, "*S"]) -> Float[Array, "*S"]:
    """Meteorological visibility 3.912 / beta of an extinction coefficient [m]; +inf at beta = 0."""
    return _contrast_limit(_float(extinction_1pm), KOSCHMIEDER_CONSTANT)


def contrast_transmission(
    range_m: Float[ArrayLike, "*S"], extinction_1pm: Float[ArrayLike, "*S"]
) -> Float[Array, "*S"]:
    """C(r) / C0 = exp(-beta r) [-]: the share of an object's contrast left at range r; 1 if beta = 0."""
    return jnp.exp(-_float(extinction_1pm) * range_m)


def apparent_contrast(
    range_m: Float[ArrayLike, "*S"], extinction_1pm: Float[ArrayLike, "*S"],
    intrinsic_contrast: Float[ArrayLike, "*S"] = 1.0,
) -> Float[Array, "*S"]:
    """Koschmieder's apparent contrast C(r) = C0 exp(-beta r) [-]."""
    return intrinsic_contrast * contrast_transmission(range_m, extinction_1pm)


def _contrast_limit(beta: Array, nepers) -> Array:
    """nepers / beta, +inf at beta <= 0 with a finite (zero) derivative there."""
    murky = beta > 0.0
    safe = jnp.where(murky, beta, 1.0)
    return jnp.where(murky, nepers / safe, jnp.inf)


def contrast_range_m(
    extinction_1pm: Float[ArrayLike, "*S"], intrinsic_contrast: Float[ArrayLike, "*S"] = 1.0,
    threshold: Float[ArrayLike, "*S"] = KOSCHMIEDER_THRESHOLD,
) -> Float[Array, "*S"]:
    """Range where the apparent contrast falls to the threshold, ln(C0 / eps) / beta [m].

    It is the visibility for C0 = 1 and eps = 2 %, and +inf in clear weather (beta = 0).
    """
    beta = _float(extinction_1pm)
    nepers = jnp.log(jnp.asarray(intrinsic_contrast, beta.dtype) / threshold)
    return _contrast_limit(beta, nepers)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Weather:
    """The weather a scene is seen in: ODD parameters, differentiable like sensor parameters.

    Attributes:
        rain_mm_h: rain rate [mm/h] (0: no rain). Radar: ITU-R P.838-3 two-way attenuation;
            camera: an optical extinction added to fog's.
        fog_visibility_m: meteorological visibility of fog [m] (+inf: no fog). Camera only:
            Koschmieder's contrast range limits how far it sees.
    The default is clear weather, under which every sensor model is unchanged bit for bit.
    """

    rain_mm_h: Float[ArrayLike, ""] = 0.0
    fog_visibility_m: Float[ArrayLike, ""] = math.inf

    def radar_loss_db(self, range_m: Float[Array, "*S"]) -> Float[Array, "*S"]:
        """Two-way rain loss of an echo from `range_m` [dB]; exactly 0 without rain."""
        return rain_two_way_loss_db(range_m, jnp.asarray(self.rain_mm_h, range_m.dtype))

    def camera_range_m(self, dtype) -> Float[Array, ""]:
        """How far the camera resolves a vehicle's contrast [m]; +inf in clear weather."""
        beta = camera_extinction_1pm(jnp.asarray(self.fog_visibility_m, dtype), jnp.asarray(self.rain_mm_h, dtype))
        return contrast_range_m(beta)


CLEAR = Weather()
