"""Sensor parameters r (differentiable pytrees) and sensor constants (static configs).

A sensor is described by two objects:

- its *parameters* r (`RadarParams`, `CameraParams`): small frozen pytrees of scalars in the
  units their names carry (`hfov_deg`, `range_m`, ...). Any leaf may be a traced value, so
  `jax.grad` with respect to any of them works. `with_param` swaps one in.
- its *config* (`RadarConfig`, `CameraConfig`): frozen, hashable dataclasses of constants loaded
  from `configs/sensors/*.toml` (static under `jit`); `config.params` holds the default r.

`param_specs` says which parameters are differentiable for a sensor, their physical domain and
default; `make_params` builds checked parameters and refuses an out-of-domain value with one
`InputError` line.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any, Literal

import jax

from diffsense import config as _config
from diffsense.errors import InputError
from diffsense.sensors._laws import CameraDetection, RadarDetection
from diffsense.sensors._mount import MOUNT_DOMAINS, check_mount

SensorName = Literal["radar", "camera"]
SENSORS: tuple[str, ...] = ("radar", "camera")


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class RadarParams:
    """Differentiable radar parameters r; each a scalar (float or traced array).

    Attributes:
        hfov_deg: horizontal field of view [deg]; also sets the antenna gain.
        vfov_deg: vertical field of view [deg]; enters through the antenna gain only (flat road).
        range_m: maximum instrumented range [m].
        tx_power_dbm: transmit power [dBm].
        noise_figure_db: receiver noise figure [dB].
        yaw_deg, mount_x_m, mount_y_m: the mounting (`diffsense.sensors._mount`); None: the config's.
    """

    hfov_deg: float
    vfov_deg: float
    range_m: float
    tx_power_dbm: float
    noise_figure_db: float
    yaw_deg: float | None = None
    mount_x_m: float | None = None
    mount_y_m: float | None = None


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class CameraParams:
    """Differentiable stereo-camera parameters r; each a scalar (float or traced array).

    Attributes:
        hfov_deg: horizontal field of view [deg] (equidistant lens: k = width_px / hfov_rad).
        range_m: maximum detection range [m].
        width_px: horizontal image resolution [px] (continuous relaxation of an integer).
        baseline_m: stereo baseline [m].
        yaw_deg, mount_x_m, mount_y_m: the mounting (`diffsense.sensors._mount`); None: the config's.
    """

    hfov_deg: float
    range_m: float
    width_px: float
    baseline_m: float
    yaw_deg: float | None = None
    mount_x_m: float | None = None
    mount_y_m: float | None = None


@dataclasses.dataclass(frozen=True)
class ParamSpec:
    """One differentiable parameter: its name, unit, physical domain and default.

    The domain is `lower < value <= upper` when `lower_open`, else `lower <= value <= upper`.
    """

    name: str
    unit: str
    lower: float
    upper: float
    lower_open: bool
    default: float
    doc: str

    def contains(self, value: float) -> bool:
        above = value > self.lower if self.lower_open else value >= self.lower
        return bool(math.isfinite(value) and above and value <= self.upper)

    def describe(self) -> str:
        left = "(" if self.lower_open else "["
        return f"{left}{self.lower:g}, {self.upper:g}] {self.unit}"


# Physical domains (not user choices, so they live here rather than in a config). The upper
# bounds of range and power are generous validity limits of the models, finite so that a
# solver can normalise the interval.
_DOMAINS: dict[str, dict[str, tuple[str, float, float, bool, str]]] = {
    "radar": {
        "hfov_deg": ("deg", 0.0, 360.0, True, "horizontal field of view"),
        "vfov_deg": ("deg", 0.0, 180.0, True, "vertical field of view"),
        "range_m": ("m", 0.0, 1000.0, True, "maximum range"),
        "tx_power_dbm": ("dBm", -30.0, 40.0, False, "transmit power"),
        "noise_figure_db": ("dB", 0.0, 30.0, False, "receiver noise figure"),
    } | MOUNT_DOMAINS,
    "camera": {
        "hfov_deg": ("deg", 0.0, 360.0, True, "horizontal field of view"),
        "range_m": ("m", 0.0, 1000.0, True, "maximum detection range"),
        "width_px": ("px", 1.0, 16384.0, False, "horizontal resolution"),
        "baseline_m": ("m", 0.0, 2.0, True, "stereo baseline"),
    } | MOUNT_DOMAINS,
}


def _is_concrete_number(value: Any) -> bool:
    if isinstance(value, jax.core.Tracer):
        return False
    try:
        float(value)
    except (TypeError, ValueError):
        return False
    return True


def _sensor_of(obj: Any) -> str:
    if isinstance(obj, (RadarParams, RadarConfig)):
        return "radar"
    if isinstance(obj, (CameraParams, CameraConfig)):
        return "camera"
    raise InputError(f"not a sensor parameter set or config: {type(obj).__name__}")


def check_params(params: RadarParams | CameraParams) -> RadarParams | CameraParams:
    """Refuse (InputError, one line) any concrete parameter outside its physical domain."""
    sensor = _sensor_of(params)
    for name, (unit, lo, hi, lo_open, doc) in _DOMAINS[sensor].items():
        value = getattr(params, name)
        if not _is_concrete_number(value) or getattr(value, "ndim", 0) != 0:
            continue  # traced or batched values are the caller's (solver's) business
        spec = ParamSpec(name, unit, lo, hi, lo_open, math.nan, doc)
        if not spec.contains(float(value)):
            raise InputError(
                f"{sensor} {name} = {float(value):g} is outside its domain {spec.describe()}"
            )
    return params


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


def _sensor_name(sensor: str) -> str:
    if sensor not in SENSORS:
        raise InputError(f"unknown sensor {sensor!r} (known: {', '.join(SENSORS)})")
    return sensor


PROFILES: tuple[str, ...] = ("physical", "paper")


def load_config(sensor: SensorName, path: str | Path | None = None, profile: str = "physical") -> RadarConfig | CameraConfig:
    """The sensor's constants: the shipped profile, with the keys of the user TOML at `path`
    (any subset of them; unknown keys and wrong types are refused) replacing its.

    Profiles: "physical" is `configs/sensors/<sensor>.toml`; "paper" is that file with the keys
    of `configs/sensors/paper/<sensor>.toml` replacing its (the paper's experimental design).
    """
    cls = _CONFIG_CLASSES[_sensor_name(sensor)]
    if profile not in PROFILES:
        raise InputError(f"unknown profile {profile!r} (known: {', '.join(PROFILES)})")
    shipped = [f"sensors/{sensor}.toml"] + ([f"sensors/paper/{sensor}.toml"] if profile == "paper" else [])
    return _config.load_layers(cls, shipped, path)


def param_specs(
    sensor: SensorName, config: RadarConfig | CameraConfig | None = None
) -> tuple[ParamSpec, ...]:
    """The differentiable parameters of `sensor`, with domains and defaults (from `config`)."""
    sensor = _sensor_name(sensor)
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


def with_param(params: RadarParams | CameraParams, name: str, value: Any) -> RadarParams | CameraParams:
    """`params` with parameter `name` replaced by `value` (which may be traced); unchecked."""
    sensor = _sensor_of(params)
    if name not in _DOMAINS[sensor]:
        known = ", ".join(_DOMAINS[sensor])
        raise InputError(f"unknown {sensor} parameter {name!r} (known: {known})")
    return dataclasses.replace(params, **{name: value})
