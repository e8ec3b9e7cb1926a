"""Stereo camera with an equidistant lens: resolvability, occlusion, stereo depth noise.

Pixels per radian k = width_px / HFOV_rad (f-theta projection: finite at 180 deg and beyond).
A vehicle is detected when its centre is in the FOV, within range, at least `min_width_px` wide
in the image (k times its angular width) and at least `min_visible_fraction` of its angular
interval is not covered by nearer vehicles:
p = gate(FOV) gate(range) gate(width_px - min) gate(visible - 0.6).
Measurements: depth along the ray with sigma_Z = Z^2 disparity_error / (k baseline) and bearing
with sigma = bearing_error_px / k. Fog and rain (`Weather`) cap the range at Koschmieder's
contrast range.

With `[detection] law = "confidence"` (`_laws.py`) the gates give way to the physical probability
that the detector's noisy confidence clears its threshold, the confidence's mean growing with
the object's width in pixels and its visible fraction (inside the image and unhidden).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from diffsense.scene import Scene
from diffsense.sensors._config import CameraConfig, load_config, param_specs
from diffsense.sensors._datatypes import Detections
from diffsense.sensors._gates import Mode
from diffsense.sensors._geometry import Tracks, polar, vehicle_occlusion
from diffsense.sensors._laws import (
    LogProbability,
    confidence_mean,
    in_fov_fraction,
    log_confidence_above,
    log_reported_below,
)
from diffsense.sensors._measure import KeyOrNoise, detect_of, p_detect_of
from diffsense.sensors._mount import mount_of
from diffsense.sensors._params import CameraParams, ParamSpec
from diffsense.sensors._sensor import Sensor, params_of
from diffsense.sensors._weather import CLEAR, Weather


def camera_px_per_rad(params: CameraParams) -> Float[Array, ""]:
    """Pixels per radian of the equidistant lens, k = width_px / HFOV_rad [px/rad]."""
    return params.width_px / jnp.deg2rad(params.hfov_deg)


def camera_accuracy_px_per_rad(params: CameraParams, config: CameraConfig) -> Float[Array, ""]:
    """Pixels per radian that set the measurement accuracy: the lens's k (physical profile), or
    the fixed `focal_length_px` when `accuracy_follows_hfov` is off (the paper profile: an
    object-list sensor whose accuracy is Table II's whatever the swept HFOV) [px/rad]."""
    if config.accuracy_follows_hfov:
        return camera_px_per_rad(params)
    # The float type of float parameters (as the lens's k has); for Python numbers or integers
    # a weak type, so a float32 scene's measurements stay float32.
    dtype = getattr(params.hfov_deg, "dtype", None)
    if dtype is not None and jnp.issubdtype(dtype, jnp.floating):
        return jnp.full_like(params.hfov_deg, config.focal_length_px)  # keeps a weak type too
    return jnp.asarray(config.focal_length_px)


def camera_depth_sigma_m(
    range_m: Float[Array, "*S"], params: CameraParams, config: CameraConfig
) -> Float[Array, "*S"]:
    """Stereo depth noise sigma_Z = Z^2 disparity_error / (k baseline) [m]."""
    k = camera_accuracy_px_per_rad(params, config)
    return range_m**2 * config.disparity_error_px / (k * params.baseline_m)


def _confidence_log_p(width_px, visible, limit_m, range_m, depth_sigma_m, config: CameraConfig) -> LogProbability:
    """The "confidence" law: P(confidence >= threshold) P(measured depth <= limit), in log space."""
    law = config.detection
    mean = confidence_mean(width_px, visible, confidence_max=law.confidence_max, width50_px=law.width50_px,
                           width_scale_px=law.width_scale_px)
    return LogProbability(log_confidence_above(mean, law.threshold, law.sigma)
                          + log_reported_below(limit_m, range_m, depth_sigma_m))


def _camera_terms(tracks: Tracks, params: CameraParams, config: CameraConfig, mode: Mode,
                  temperature, weather: Weather = CLEAR):
    mount = mount_of(params, config)
    range_m, azimuth_rad = polar(tracks, mount)
    tau = config.temperature
    half, hidden = vehicle_occlusion(tracks, range_m, azimuth_rad, mount, mode,
                                     tau.near_m * temperature, tau.overlap_deg * temperature)
    k = camera_px_per_rad(params)
    # Fog and rain cap the range at Koschmieder's contrast range (+inf in clear weather, so
    # the minimum is then the range itself, bit for bit).
    limit_m = jnp.minimum(params.range_m, weather.camera_range_m(range_m.dtype))
    depth_sigma = camera_depth_sigma_m(range_m, params, config)
    if config.detection.law == "confidence":
        gates = _confidence_log_p(k * 2.0 * half, in_fov_fraction(azimuth_rad, half, params.hfov_deg) * (1.0 - hidden),
                                  limit_m, range_m, depth_sigma, config)
    else:
        gates = (
            (0.5 * params.hfov_deg - jnp.rad2deg(jnp.abs(azimuth_rad)), tau.fov_deg * temperature),
            (limit_m - range_m, tau.range_m * temperature),
            (k * 2.0 * half - config.min_width_px, tau.width_px * temperature),
            ((1.0 - hidden) - config.min_visible_fraction, tau.visible * temperature),
        )
    bearing_sigma = config.bearing_error_px / camera_accuracy_px_per_rad(params, config) * jnp.ones_like(range_m)
    return gates, range_m, azimuth_rad, depth_sigma, bearing_sigma


def camera_p_detect(
    scene: Scene, params: CameraParams, config: CameraConfig, *, mode: Mode = "soft",
    temperature: float | Float[Array, ""] = 1.0, weather: Weather = CLEAR,
) -> Float[Array, "T V"]:
    """Camera detection probability [T, V] (soft, differentiable in `params`) or 0/1 (hard).

    `temperature` scales every soft-gate temperature of `config` (temperature continuation).
    """
    return p_detect_of(_camera_terms, scene, params, config, mode, temperature, weather)


def camera_detect(
    scene: Scene, params: CameraParams, config: CameraConfig, key: KeyOrNoise, *,
    mode: Mode = "soft", temperature: float | Float[Array, ""] = 1.0, weather: Weather = CLEAR,
) -> Detections:
    """Camera `Detections` [T, V]: p_detect and noisy stereo depth/bearing in the world."""
    return detect_of(_camera_terms, scene, params, config, key, mode, temperature, weather)


class Camera(Sensor):
    """The stereo camera: equidistant lens, resolvability, stereo depth noise, occlusion.

    `config` holds every constant (`configs/sensors/camera.toml`, or a user TOML via
    `Camera.from_toml`); its `params` are the defaults of r.
    """

    config: CameraConfig = eqx.field(static=True)
    kind: ClassVar[str] = "camera"

    @classmethod
    def from_toml(cls, path: str | Path | None = None, profile: str = "physical") -> Camera:
        """The camera of the shipped `profile` ("physical" or "paper"), with the keys of the TOML
        at `path` (any subset of its constants) replacing the profile's."""
        return cls(load_config("camera", path, profile))

    def param_specs(self) -> tuple[ParamSpec, ...]:
        return param_specs("camera", self.config)

    @property
    def mount_x_m(self) -> float:
        return float(self.config.mount_x_m)

    def _detect(self, scene: Scene, r: dict[str, Any], noise: KeyOrNoise, mode: Mode, temperature, weather) -> Detections:
        return camera_detect(scene, params_of(CameraParams, r), self.config, noise, mode=mode, temperature=temperature,
                             weather=weather)
