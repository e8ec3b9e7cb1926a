"""Sensor parameters r: small frozen pytrees, their physical domains and their checks.

A sensor's *parameters* r (`RadarParams`, `CameraParams`) are small frozen pytrees of scalars in
the units their names carry (`hfov_deg`, `range_m`, ...). Any leaf may be a traced value, so
`jax.grad` with respect to any of them works. `with_param` swaps one in; `check_params` refuses a
concrete value outside its physical domain with one `InputError` line. The sensor's constants
(its *config*) live in `_config.py`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Literal

import jax
import numpy as np

from diffsense.runtime import InputError
from diffsense.sensors._mount import MOUNT_DOMAINS

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

    def check(self, value: Any) -> None:
        """Refuse (InputError, one line), on the host, a concrete value this parameter cannot
        take: not one number, not finite, or outside the domain. A traced value passes: it is
        a solver's, kept in its box by construction."""
        if isinstance(value, jax.core.Tracer):
            return
        try:
            number = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError(f"{self.name} must be a number, got {type(value).__name__}") from None
        if number.ndim != 0:
            raise InputError(f"{self.name} must be one number, got an array of shape {number.shape} "
                             "(vmap over r for many)")
        if not self.contains(float(number)):
            raise InputError(f"{self.name} = {float(number):g} is outside its domain {self.describe()}")


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


def _sensor_of(params: Any) -> str:
    if isinstance(params, RadarParams):
        return "radar"
    if isinstance(params, CameraParams):
        return "camera"
    raise InputError(f"not a sensor parameter set: {type(params).__name__}")


def sensor_name(sensor: str) -> str:
    """`sensor` if it is a known sensor kind, else one `InputError` line."""
    if sensor not in SENSORS:
        raise InputError(f"unknown sensor {sensor!r} (known: {', '.join(SENSORS)})")
    return sensor


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


def with_param(params: RadarParams | CameraParams, name: str, value: Any) -> RadarParams | CameraParams:
    """`params` with parameter `name` replaced by `value` (which may be traced); unchecked."""
    sensor = _sensor_of(params)
    if name not in _DOMAINS[sensor]:
        known = ", ".join(_DOMAINS[sensor])
        raise InputError(f"unknown {sensor} parameter {name!r} (known: {known})")
    return dataclasses.replace(params, **{name: value})
