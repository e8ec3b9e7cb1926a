"""Where a sensor sits on the ego and where it looks: the mounting, as differentiable parameters.

Every sensor has three mounting parameters besides its own: `yaw_deg` (the boresight,
counter-clockwise from the ego's heading), `mount_x_m` (ahead of the ego's reference point, its
body centre in the scene) and `mount_y_m` (to the left of the ego's centre line). Their defaults
are the sensor config's top-level `yaw_deg`, `mount_x_m`, `mount_y_m`; the envelope below is
their domain. The geometry (`_geometry.py`) measures ranges and azimuths from the mount point
in the sensor's frame, so the FOV gate is centred on the yaw and occlusion is seen from there.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import jax

from diffsense.runtime import InputError

# The envelope, in the ego's body frame. x runs from the rear bumper of the shipped car (4.6 m
# long: -2.3 m) to the paper's radar mounting (4.2 m: its CarMaker coordinates, which the
# centre reference places ahead of the 2.3 m front bumper; kept so that the defaults are the
# paper's, and so that the scene's relevance box, which reaches the sensors, needs no change).
# y stays within the shipped car's half-width (1.8 m wide). Yaw may turn the boresight to any
# direction. The ego's own body hides nothing: it is not an occluder.
MOUNT_DOMAINS: dict[str, tuple[str, float, float, bool, str]] = {
    "yaw_deg": ("deg", -180.0, 180.0, False, "mounting yaw (boresight from the ego heading, left +)"),
    "mount_x_m": ("m", -2.3, 4.2, False, "mounting position ahead of the ego's body centre"),
    "mount_y_m": ("m", -0.9, 0.9, False, "mounting position left of the ego's centre line"),
}
MOUNT_NAMES: tuple[str, ...] = tuple(MOUNT_DOMAINS)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Mount:
    """A sensor's pose on the ego, each a scalar (float or traced).

    Attributes:
        x_m: ahead of the ego's body centre [m].
        y_m: left of the ego's centre line [m].
        yaw_rad: boresight, counter-clockwise from the ego's heading [rad].
    """

    x_m: Any
    y_m: Any = 0.0
    yaw_rad: Any = 0.0


def as_mount(mount: Mount | float) -> Mount:
    """A `Mount`; a bare number is a forward-facing sensor that far ahead on the centre line."""
    return mount if isinstance(mount, Mount) else Mount(x_m=mount)


def is_static_zero(value: Any) -> bool:
    """True for a Python number equal to 0 (not a traced or array value)."""
    return isinstance(value, (int, float)) and value == 0


def mount_of(params: Any, config: Any) -> Mount:
    """The mounting of a sensor's parameters, the config's where they leave it None."""
    def pick(name):
        value = getattr(params, name)
        return getattr(config, name) if value is None else value

    yaw_deg = pick("yaw_deg")
    # A static zero yaw stays a Python 0.0 (not an array), so that the geometry can skip it.
    yaw_rad = 0.0 if is_static_zero(yaw_deg) else yaw_deg * (math.pi / 180.0)
    return Mount(x_m=pick("mount_x_m"), y_m=pick("mount_y_m"), yaw_rad=yaw_rad)


def check_mount(sensor: str, config: Any) -> None:
    """Refuse (InputError, one line) a config whose mounting leaves the envelope, or a mounting
    given in its `[params]` (the mounting's defaults are the config's top-level keys)."""
    for name, (unit, lo, hi, _, _) in MOUNT_DOMAINS.items():
        if getattr(config.params, name) is not None:
            raise InputError(f"{sensor} {name} is a top-level key of the sensor config, not a [params] one")
        value = getattr(config, name)
        if not (isinstance(value, (int, float)) and math.isfinite(value) and lo <= value <= hi):
            raise InputError(f"{sensor} {name} = {value!r} is outside its envelope [{lo:g}, {hi:g}] {unit}")


@dataclasses.dataclass(frozen=True)
class ReachStandIn:
    """Stands in for a sensor in the scenes' relevance test, which keeps what can hide a vehicle
    from sensors up to `mount_x_m` ahead of the ego's centre (`metrics.relevance_reach`)."""

    mount_x_m: float


def relevance_stand_ins(params: Mapping[str, tuple[float, float]]) -> list[ReachStandIn]:
    """One stand-in at the upper bound of every free `mount_x_m` in `params`: a solve may move the
    sensor that far forward, and the scenes must keep what could hide a vehicle from there."""
    return [ReachStandIn(float(hi)) for name, (_, hi) in params.items() if name.rsplit(".", 1)[-1] == "mount_x_m"]


def _mount_name(name: Any, what: str) -> str:
    if name not in MOUNT_DOMAINS:
        raise InputError(f"{what}: unknown mounting parameter {name!r} (known: {', '.join(MOUNT_NAMES)})")
    return name


def _in_global(name: str, value: Any, what: str) -> float:
    """`value` as a float if it is a number inside the global envelope of `name`; InputError otherwise."""
    unit, lo, hi, _, _ = MOUNT_DOMAINS[name]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(f"{what} {name} must be a finite number [{unit}], got {value!r}")
    if not lo <= value <= hi:
        raise InputError(f"{what} {name} = {value:g} is outside the mounting envelope [{lo:g}, {hi:g}] {unit}")
    return float(value)


def _bounds(name: str, bounds: Any, what: str) -> tuple[float, float]:
    try:
        lo, hi = bounds
    except (TypeError, ValueError):
        raise InputError(f"{what} envelope {name} must be two numbers [LO, HI], got {bounds!r}") from None
    lo, hi = (_in_global(name, b, f"{what} envelope") for b in (lo, hi))
    if not lo < hi:
        raise InputError(f"{what} envelope {name} must have LO < HI, got {lo:g} {hi:g}")
    return lo, hi


@dataclasses.dataclass(frozen=True)
class Mounting:
    """A suite member's place on the ego: its mounting defaults and the envelope a solve may move
    it in (two corner radars of one kind sit in different places; `Suite(mountings=...)`).

    Attributes:
        defaults: {name: value} replacing the sensor's own mounting defaults (names in
            `MOUNT_NAMES`; deg or m), inside the global envelope `MOUNT_DOMAINS`.
        envelope: {name: (lo, hi)}: the member's own domain of each named mounting parameter,
            inside the global envelope; a parameter left out keeps the global one.
    Both may be given as mappings; they are held as tuples in `MOUNT_NAMES` order (a Suite's
    static field must be hashable). Whether each default lies in its envelope is checked by the
    Suite, which knows the sensor's own defaults.
    """

    defaults: Any = ()
    envelope: Any = ()

    def __post_init__(self):
        defaults = dict(self.defaults)  # a mapping, or the held ((name, value), ...)
        envelope = (dict(self.envelope) if isinstance(self.envelope, Mapping)
                    else {n: (lo, hi) for n, lo, hi in self.envelope})  # or the held ((name, lo, hi), ...)
        for name in (*defaults, *envelope):
            _mount_name(name, "mounting")
        object.__setattr__(self, "defaults", tuple(
            (n, _in_global(n, defaults[n], "mounting default")) for n in MOUNT_NAMES if n in defaults))
        object.__setattr__(self, "envelope", tuple(
            (n, *_bounds(n, envelope[n], "mounting")) for n in MOUNT_NAMES if n in envelope))

    def default(self, name: str, fallback: float) -> float:
        """The member's default of mounting parameter `name`, `fallback` (the sensor's) if not set."""
        return next((v for n, v in self.defaults if n == name), fallback)

    def domain(self, name: str) -> tuple[float, float]:
        """The member's envelope (lo, hi) of mounting parameter `name` [deg or m]."""
        _, lo, hi, _, _ = MOUNT_DOMAINS[name]
        return next(((a, b) for n, a, b in self.envelope if n == name), (lo, hi))

    def names(self) -> set[str]:
        """The mounting parameters it sets a default or an envelope for."""
        return {n for n, _ in self.defaults} | {n for n, _, _ in self.envelope}
