"""A problem's named parameters: full names from short or qualified ones, and checked bounds."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from diffsense.runtime import InputError, finite_number
from diffsense.sensors._mount import MOUNT_NAMES
from diffsense.sensors._sensor import Sensor


def resolve_name(sensor: Sensor, name: str) -> str:
    """A parameter's full name from a full ("hfov_deg"), short ("hfov") or qualified
    ("radar.hfov_deg", "corner_left.hfov": by the suite member's name) one; InputError naming
    the known ones otherwise."""
    specs = [s.name for s in sensor.param_specs()]
    if name in specs:
        return name
    members = getattr(sensor, "members", None)
    if members is not None:  # a suite: "member.param", the param resolved within the member
        kind, dot, rest = name.partition(".")
        if not dot:
            raise InputError(f"a suite's parameters are qualified by the sensor: give e.g. "
                             f"{', '.join(n + '.' + name for n in sensor.names)}")
        if kind not in sensor.names:
            raise InputError(f"parameter {name} names sensor {kind!r}, not in the suite ({', '.join(sensor.names)})")
        return f"{kind}.{resolve_name(members[sensor.names.index(kind)], rest)}"
    if "." in name:
        kind, name = name.split(".", 1)
        if kind != sensor.kind:
            raise InputError(f"parameter {kind}.{name} names sensor {kind!r}, not in this problem ({sensor.kind})")
    if name in specs:
        return name
    short = {s.rsplit("_", 1)[0]: s for s in specs}
    if name in short:
        return short[name]
    known = ", ".join(f"{k} ({v})" for k, v in short.items())
    raise InputError(f"unknown {sensor.kind} parameter {name!r} (known: {known})")


def resolve_params(sensor: Sensor, params: Mapping[str, Any]) -> dict[str, tuple[float, float]]:
    if not isinstance(params, Mapping) or not params:
        raise InputError("params must name at least one parameter with its bounds, e.g. {'hfov_deg': (30, 180)}")
    out: dict[str, tuple[float, float]] = {}
    for raw, bounds in params.items():
        name = resolve_name(sensor, str(raw))
        if name in out:
            raise InputError(f"parameter {name} is named twice")
        try:
            lo, hi = (finite_number(b, f"bounds of {name}") for b in bounds)
        except InputError:  # a bound that is no number, or not finite: its own message
            raise
        except (TypeError, ValueError):
            raise InputError(f"bounds of {name} must be two numbers (lo, hi), got {bounds!r}") from None
        if not lo < hi:
            raise InputError(f"bounds of {name} must have lo < hi, got {lo:g} {hi:g}")
        spec = sensor.spec(name)
        for value in (lo, hi):
            if not spec.contains(value):
                # A mounting parameter's domain is its envelope (a suite member's own, or the global one).
                what = " (its mounting envelope)" if name.rsplit(".", 1)[-1] in MOUNT_NAMES else ""
                raise InputError(f"bounds {lo:g} {hi:g} are outside the domain of {name}: {spec.describe()}{what}")
        out[name] = (lo, hi)
    return out
