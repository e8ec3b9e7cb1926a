"""Sensor constants (static configs) and the differentiable parameters they offer.

A sensor's *config* (`RadarConfig`, `CameraConfig`) is a frozen, hashable dataclass of constants
loaded from `configs/sensors/*.toml` (static under `jit`); `config.params` holds its default r.
`param_specs` says which parameters are differentiable for a sensor, their physical domain and
their default under a config; `make_params` builds checked parameters from a config's defaults.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from diffsense import config as _config
from diffsense.runtime import InputError
from diffsense.sensors._laws import CameraDetection, RadarDetection
from diffsense.sensors._mount import check_mount
from diffsense.sensors._params import (
    _DOMAINS,
    CameraParams,
    ParamSpec,
    RadarParams,
    SensorName,
    check_params,
    sensor_name,
    with_param,
)


@dataclasses.dataclass(frozen=True)
class RadarTemperatures:
    """Soft-gate temperatures of the radar, in the units of each gate's margin."""

    fov_deg: float
    range_m: float
    snr_db: float
    near_m: float
    overlap_deg: float

    def __post_init__(self):
        _check_positive("radar temperature", self)


@dataclasses.dataclass(frozen=True)
class RadarConfig:
    """Radar constants (Table I of the paper and documented engineering values); static."""

    params: RadarParams
    temperature: RadarTemperatures
    mount_x_m: float
    frequency_ghz: float
    noise_bandwidth_hz: float
    antenna_efficiency: float
    system_loss_db: float
    atmospheric_loss_db_per_km: float
    processing_gain_db: float
    snr_threshold_db: float
    rcs_car_dbsm: float
    rcs_van_dbsm: float
    rcs_truck_dbsm: float
    occlusion_loss_db: float
    range_accuracy_m: float
    azimuth_accuracy_deg: float
    range_resolution_m: float
    azimuth_resolution_deg: float
    gain_follows_hfov: bool = True
    gain_beam_deg: float = 30.0
    detection: RadarDetection = RadarDetection()  # the detection law (`_laws.py`)
    mount_y_m: float = 0.0
    yaw_deg: float = 0.0

    def __post_init__(self):
        check_params(self.params)
        check_mount("radar", self)
        for name in ("frequency_ghz", "noise_bandwidth_hz", "antenna_efficiency"):
            _require(getattr(self, name) > 0, f"radar {name} must be > 0")
        _require(self.antenna_efficiency <= 1, "radar antenna_efficiency must be <= 1")
        _require(0 < self.gain_beam_deg <= 360, "radar gain_beam_deg must be in (0, 360]")
        for name in ("system_loss_db", "atmospheric_loss_db_per_km", "occlusion_loss_db",
                     "range_accuracy_m", "azimuth_accuracy_deg", "range_resolution_m",
                     "azimuth_resolution_deg"):
            _require(getattr(self, name) >= 0, f"radar {name} must be >= 0")


@dataclasses.dataclass(frozen=True)
class CameraTemperatures:
    """Soft-gate temperatures of the camera, in the units of each gate's margin."""

    fov_deg: float
    range_m: float
    width_px: float
    visible: float
    near_m: float
    overlap_deg: float

    def __post_init__(self):
        _check_positive("camera temperature", self)


@dataclasses.dataclass(frozen=True)
class CameraConfig:
    """Stereo-camera constants (Table II of the paper and documented values); static."""

    params: CameraParams
    temperature: CameraTemperatures
    mount_x_m: float
    disparity_error_px: float
    bearing_error_px: float
    min_width_px: float
    min_visible_fraction: float
    accuracy_follows_hfov: bool = True
    focal_length_px: float = 2400.0
    detection: CameraDetection = CameraDetection()  # the detection law (`_laws.py`)
    mount_y_m: float = 0.0
    yaw_deg: float = 0.0

    def __post_init__(self):
        check_params(self.params)
        check_mount("camera", self)
        for name in ("disparity_error_px", "bearing_error_px", "min_width_px"):
            _require(getattr(self, name) >= 0, f"camera {name} must be >= 0")
        _require(self.focal_length_px > 0, "camera focal_length_px must be > 0")
        _require(0 <= self.min_visible_fraction <= 1,
                 "camera min_visible_fraction must be in [0, 1]")


def _require(ok: bool, message: str) -> None:
    if not ok:
        raise InputError(message)


def default_value(config: Any, name: str) -> float:
    """The default of parameter `name`: the config's `params`, or its mounting for those."""
    value = getattr(config.params, name)
    return float(getattr(config, name) if value is None else value)


def _check_positive(what: str, obj: Any) -> None:
    for f in dataclasses.fields(obj):
        _require(getattr(obj, f.name) > 0, f"{what} {f.name} must be > 0")


_CONFIG_CLASSES = {"radar": RadarConfig, "camera": CameraConfig}


PROFILES: tuple[str, ...] = ("physical", "paper")


def load_config(sensor: SensorName, path: str | Path | None = None, profile: str = "physical") -> RadarConfig | CameraConfig:
    """The sensor's constants: the shipped profile, with the keys of the user TOML at `path`
    (any subset of them; unknown keys and wrong types are refused) replacing its.

    Profiles: "physical" is `configs/sensors/<sensor>.toml`; "paper" is that file with the keys
    of `configs/sensors/paper/<sensor>.toml` replacing its (the paper's experimental design).
    """
    cls = _CONFIG_CLASSES[sensor_name(sensor)]
    if profile not in PROFILES:
        raise InputError(f"unknown profile {profile!r} (known: {', '.join(PROFILES)})")
    shipped = [f"sensors/{sensor}.toml"] + ([f"sensors/paper/{sensor}.toml"] if profile == "paper" else [])
    return _config.load_layers(cls, shipped, path)


def param_specs(
    sensor: SensorName, config: RadarConfig | CameraConfig | None = None
) -> tuple[ParamSpec, ...]:
    """The differentiable parameters of `sensor`, with domains and defaults (from `config`)."""
    sensor = sensor_name(sensor)
    config = load_config(sensor) if config is None else config
    return tuple(
        ParamSpec(name, unit, lo, hi, lo_open, default_value(config, name), doc)
        for name, (unit, lo, hi, lo_open, doc) in _DOMAINS[sensor].items()
    )


def make_params(config: RadarConfig | CameraConfig, **values: float) -> RadarParams | CameraParams:
    """The config's default parameters with `values` replaced, checked against their domains."""
    params = config.params
    for name, value in values.items():
        params = with_param(params, name, value)
    return check_params(params)
