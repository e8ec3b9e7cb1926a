"""Radar: SNR from the radar equation with the antenna gain tied to the beam, and its detections.

SNR_dB = Pt + 2 G + 20 log10(lambda) + RCS - 30 log10(4 pi) - 40 log10(R) - N - L - 2 a R + Gp,
with G = 10 log10(eta 4 pi / (HFOV_rad VFOV_rad)) [dBi], the noise floor
N = -174 + 10 log10(B) + NF [dBm], system loss L, one-way atmospheric loss a [dB/m] and processing
gain Gp (values and their sources: configs/sensors/radar.toml). Widening the HFOV lowers both
gains: doubling it costs 6.02 dB, and each doubling of range costs 12.04 dB (+ atmosphere).

p = gate(HFOV/2 - |azimuth|) gate(R_max - R) gate(SNR - occlusion loss - threshold); an occluder
attenuates the SNR by `occlusion_loss_db` per occluded fraction instead of hiding the target.
Rain (`Weather`) attenuates the echo by its two-way ITU-R P.838-3 loss; fog does not.
Measurement noise: the Table I accuracy plus the thermal term resolution / sqrt(2 SNR).

With `[detection] law = "swerling1"` (`_laws.py`) the gates give way to the physical probability
p = Pfa^(1/(1 + SNR)) P(measured range <= range_m), the SNR taking the Gaussian beam's two-way
loss off boresight: HFOV is the beam's -3 dB width, and the SNR law alone sets the range.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from diffsense.scene import Scene
from diffsense.sensors._config import RadarConfig, load_config, param_specs
from diffsense.sensors._datatypes import Detections
from diffsense.sensors._gates import Mode
from diffsense.sensors._geometry import Tracks, polar, vehicle_occlusion
from diffsense.sensors._laws import (
    LogProbability,
    gaussian_beam_loss_db,
    log_reported_below,
    swerling1_log_pd,
)
from diffsense.sensors._measure import KeyOrNoise, detect_of, p_detect_of
from diffsense.sensors._mount import mount_of
from diffsense.sensors._params import ParamSpec, RadarParams
from diffsense.sensors._sensor import Sensor, params_of
from diffsense.sensors._weather import CLEAR, Weather

_SPEED_OF_LIGHT_MPS = 299_792_458.0
_BOLTZMANN_DBM_PER_HZ = -174.0  # kT0 at 290 K
_MIN_RANGE_M = 1e-3  # the far-field equation is meaningless below; keeps log10 finite at R = 0
_SNR_CLIP_DB = 100.0  # bounds 10^(SNR/20) in the noise term (float32-safe)


def radar_gain_dbi(params: RadarParams, config: RadarConfig) -> Float[Array, ""]:
    """One-way antenna gain of a beam of HFOV x VFOV [dBi]; with `gain_follows_hfov` off (the
    paper profile) the beam is `gain_beam_deg` wide whatever the swept HFOV."""
    hfov_deg = params.hfov_deg if config.gain_follows_hfov else config.gain_beam_deg
    beam_sr = jnp.deg2rad(hfov_deg) * jnp.deg2rad(params.vfov_deg)
    return 10.0 * jnp.log10(config.antenna_efficiency * 4.0 * math.pi / beam_sr)


def radar_snr_db(
    range_m: Float[Array, "*S"], rcs_dbsm: Float[Array, "*S"], params: RadarParams,
    config: RadarConfig,
) -> Float[Array, "*S"]:
    """SNR [dB] of a target of radar cross-section `rcs_dbsm` at `range_m` on the beam."""
    wavelength_m = _SPEED_OF_LIGHT_MPS / (config.frequency_ghz * 1e9)
    constant_db = (20.0 * math.log10(wavelength_m) - 30.0 * math.log10(4.0 * math.pi)
                   - _BOLTZMANN_DBM_PER_HZ - 10.0 * math.log10(config.noise_bandwidth_hz)
                   - config.system_loss_db + config.processing_gain_db)
    r = jnp.maximum(range_m, _MIN_RANGE_M)
    return (params.tx_power_dbm + 2.0 * radar_gain_dbi(params, config) + rcs_dbsm
            - 40.0 * jnp.log10(r) - params.noise_figure_db + constant_db
            - 2.0 * config.atmospheric_loss_db_per_km * r / 1000.0)


def radar_rcs_dbsm(kind: Int[Array, "V"], config: RadarConfig) -> Float[Array, "V"]:
    """Radar cross-section [dBsm] of each vehicle kind (CAR, VAN, TRUCK)."""
    table = jnp.asarray([config.rcs_car_dbsm, config.rcs_van_dbsm, config.rcs_truck_dbsm])
    return table[kind]


def _radar_terms(tracks: Tracks, params: RadarParams, config: RadarConfig, mode: Mode, temperature,
                 weather: Weather = CLEAR):
    mount = mount_of(params, config)
    range_m, azimuth_rad = polar(tracks, mount)
    tau = config.temperature
    _, shadow = vehicle_occlusion(tracks, range_m, azimuth_rad, mount, mode,
                                  tau.near_m * temperature, tau.overlap_deg * temperature)
    rcs = radar_rcs_dbsm(tracks.kind, config).astype(range_m.dtype)  # [V, 1]
    snr_db = radar_snr_db(range_m, rcs, params, config)
    snr_db = snr_db - config.occlusion_loss_db * shadow - weather.radar_loss_db(range_m)
    swerling = config.detection.law == "swerling1"
    if swerling:  # the antenna pattern is the azimuth edge: two-way loss off boresight
        snr_db = snr_db - 2.0 * gaussian_beam_loss_db(azimuth_rad, params.hfov_deg)
    # Thermal noise: resolution / sqrt(2 SNR), on top of the accuracy floor (Table I).
    thermal = 10.0 ** (-jnp.clip(snr_db, -_SNR_CLIP_DB, _SNR_CLIP_DB) / 20.0) / math.sqrt(2.0)
    range_sigma = jnp.sqrt(config.range_accuracy_m**2 + (config.range_resolution_m * thermal) ** 2)
    az_sigma_deg = jnp.sqrt(config.azimuth_accuracy_deg**2
                            + (config.azimuth_resolution_deg * thermal) ** 2)
    if swerling:
        # Range from the SNR law alone; `range_m` is where the radar stops reporting, applied
        # to the measured range (the Table I accuracy plus thermal noise).
        gates = LogProbability(swerling1_log_pd(snr_db, config.detection.pfa)
                               + log_reported_below(params.range_m, range_m, range_sigma))
    else:
        gates = (
            (0.5 * params.hfov_deg - jnp.rad2deg(jnp.abs(azimuth_rad)), tau.fov_deg * temperature),
            (params.range_m - range_m, tau.range_m * temperature),
            (snr_db - config.snr_threshold_db, tau.snr_db * temperature),
        )
    return gates, range_m, azimuth_rad, range_sigma, jnp.deg2rad(az_sigma_deg)


def radar_p_detect(
    scene: Scene, params: RadarParams, config: RadarConfig, *, mode: Mode = "soft",
    temperature: float | Float[Array, ""] = 1.0, weather: Weather = CLEAR,
) -> Float[Array, "T V"]:
    """Radar detection probability [T, V] (soft, differentiable in `params`) or 0/1 (hard).

    `temperature` scales every soft-gate temperature of `config` (temperature continuation).
    """
    return p_detect_of(_radar_terms, scene, params, config, mode, temperature, weather)


def radar_detect(
    scene: Scene, params: RadarParams, config: RadarConfig, key: KeyOrNoise, *,
    mode: Mode = "soft", temperature: float | Float[Array, ""] = 1.0, weather: Weather = CLEAR,
) -> Detections:
    """Radar `Detections` [T, V]: p_detect and noisy range/azimuth measurements in the world."""
    return detect_of(_radar_terms, scene, params, config, key, mode, temperature, weather)


class Radar(Sensor):
    """The 77 GHz radar: SNR from the radar equation, gain tied to the beam, soft gates.

    `config` holds every constant (`configs/sensors/radar.toml`, or a user TOML via
    `Radar.from_toml`); its `params` are the defaults of r.
    """

    config: RadarConfig = eqx.field(static=True)
    kind: ClassVar[str] = "radar"

    @classmethod
    def from_toml(cls, path: str | Path | None = None, profile: str = "physical") -> Radar:
        """The radar of the shipped `profile` ("physical" or "paper"), with the keys of the TOML
        at `path` (any subset of its constants) replacing the profile's."""
        return cls(load_config("radar", path, profile))

    def param_specs(self) -> tuple[ParamSpec, ...]:
        return param_specs("radar", self.config)

    @property
    def mount_x_m(self) -> float:
        return float(self.config.mount_x_m)

    def _detect(self, scene: Scene, r: dict[str, Any], noise: KeyOrNoise, mode: Mode, temperature, weather) -> Detections:
        return radar_detect(scene, params_of(RadarParams, r), self.config, noise, mode=mode, temperature=temperature,
                            weather=weather)
