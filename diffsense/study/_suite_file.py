"""Suite files: a sensor suite's design problem in one strict TOML (`configs/suites/*.toml`).

Named members, any number of one kind (up to `diffsense.sensors.Suite`'s six):

    description = "..."                     # optional
    cost_weight = 0.002                     # optional
    [members.front_radar]                   # a member: its name qualifies its parameters
    kind = "radar"                          # a registered sensor
    sensor_config = "../sensors/laws/radar_swerling1.toml"   # optional, relative to this file
    mount_x_m = 4.2                         # optional mounting defaults: yaw_deg, mount_x_m, mount_y_m
    [members.front_radar.envelope]          # optional: the member's own mounting envelope, within
    yaw_deg = [-10.0, 10.0]                 # the global one (diffsense.sensors.MOUNT_DOMAINS)
    [params]
    "front_radar.hfov_deg" = [20.0, 120.0]

Or members named by their kinds (one of each):

    sensors = ["radar", "camera"]          # the suite's members, fused into one track per vehicle
    cost_weight = 0.002                     # lambda in E + lambda * cost [m per currency unit]; optional
    description = "..."                     # optional
    [params]                                # the free parameters, qualified by the member, and bounds
    "radar.hfov_deg" = [20.0, 120.0]
    "camera.width_px" = [640.0, 3840.0]
    [sensor_config]                         # optional: a member's constants from a TOML, the path
    radar = "../sensors/laws/radar_swerling1.toml"   # relative to this file (`Problem.sensor_config`)

`ds.Problem.from_suite(path)` and `python -m diffsense.optimise --suite FILE` read it. Nothing else
is accepted: an unknown key or a value of the wrong type is refused in one line naming the file,
and so is what `Problem` refuses (a bound outside its domain or its member's envelope, reversed
bounds, a parameter named twice, a member not in the suite, a mounting default outside its
member's envelope). A member named twice is two tables of one name, which TOML itself refuses.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

from diffsense.config import parse_toml
from diffsense.runtime import InputError, read_text_file

_KEYS = ("sensors", "members", "cost_weight", "description", "params", "sensor_config")
T = TypeVar("T")


def _number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _fail(path: Path, message: str) -> InputError:
    return InputError(f"suite {path}: {message}")


def _read(path: Path) -> dict[str, Any]:
    return parse_toml(read_text_file(path, "suite"), f"suite {path}")


def _params(path: Path, table: Any) -> dict[str, tuple[float, float]]:
    if not isinstance(table, dict) or not table:
        raise _fail(path, "[params] must be a table naming at least one parameter, e.g. \"radar.hfov_deg\" = [20, 120]")
    out = {}
    for name, bounds in table.items():
        if isinstance(bounds, dict):  # an unquoted dotted key (radar.hfov_deg = ...) makes a sub-table
            raise _fail(path, f"quote the qualified name: \"{name}.{next(iter(bounds), '')}\" = [LO, HI]")
        if not (isinstance(bounds, list) and len(bounds) == 2 and all(_number(b) for b in bounds)):
            raise _fail(path, f"params {name} must be two numbers [LO, HI], got {bounds!r}")
        out[name] = (float(bounds[0]), float(bounds[1]))
    return out


def _sensor_config(path: Path, table: Any) -> dict[str, str]:
    """[sensor_config]: member name -> TOML path, resolved against the suite file's folder."""
    if not isinstance(table, dict) or not table:
        raise _fail(path, "[sensor_config] must be a table of member name = \"TOML path\", e.g. radar = \"radar.toml\"")
    out = {}
    for name, value in table.items():
        if not (isinstance(value, str) and value):
            raise _fail(path, f"sensor_config {name} must be a TOML path (a string), got {value!r}")
        config = path.parent / value
        if not config.is_file():
            raise _fail(path, f"sensor_config {name}: {config} is not a file")
        out[name] = str(config)
    return out


def _members(path: Path, table: Any) -> dict[str, dict[str, Any]]:
    """[members]: name -> its table (kind, ...), a sensor_config resolved against the file's folder;
    the keys and values are checked by `diffsense.study.named_members`."""
    if not isinstance(table, dict) or not table:
        raise _fail(path, "[members] must hold at least one member table, e.g. [members.front_radar] kind = \"radar\"")
    out = {}
    for name, member in table.items():
        if not isinstance(member, dict):
            raise _fail(path, f"members.{name} must be a table ([members.{name}] with kind = ...), got {member!r}")
        member = dict(member)
        config = member.get("sensor_config")
        if config is not None:
            if not (isinstance(config, str) and config):
                raise _fail(path, f"members.{name}.sensor_config must be a TOML path (a string), got {config!r}")
            if not (path.parent / config).is_file():
                raise _fail(path, f"members.{name}.sensor_config: {path.parent / config} is not a file")
            member["sensor_config"] = str(path.parent / config)
        out[name] = member
    return out


def _sensor_fields(path: Path, data: dict[str, Any]) -> dict[str, Any]:
    """The "sensor" (and "sensor_config") fields: named [members], or sensors = [...] by kind."""
    if "members" in data:
        if "sensors" in data or "sensor_config" in data:
            raise _fail(path, "give the members either as [members.NAME] tables or as sensors = [...] (with "
                              "[sensor_config]), not both; a member's table holds its sensor_config")
        return {"sensor": _members(path, data["members"])}
    sensors = data.get("sensors")
    if not (isinstance(sensors, list) and sensors and all(isinstance(s, str) and s for s in sensors)):
        raise _fail(path, f"sensors must be a list of sensor names, e.g. [\"radar\", \"camera\"], got {sensors!r} "
                          "(or give named [members.NAME] tables)")
    fields: dict[str, Any] = {"sensor": list(sensors)}
    if "sensor_config" in data:
        fields["sensor_config"] = _sensor_config(path, data["sensor_config"])
    return fields


def load_suite(path: str | Path) -> dict[str, Any]:
    """The `Problem` fields a suite file gives: {"sensor", "params", "cost_weight"} and, when it
    has one, "sensor_config", each value's type checked (the values themselves are checked by
    `Problem`). "sensor" is a list of kinds, or {member name: its table} for named members."""
    path = Path(path)
    data = _read(path)
    unknown = [k for k in data if k not in _KEYS]
    if unknown:
        raise _fail(path, f"unknown key {unknown[0]!r} (known: {', '.join(_KEYS)})")
    fields = _sensor_fields(path, data)
    if "params" not in data:
        raise _fail(path, "no [params]: name the free parameters and their bounds")
    cost_weight = data.get("cost_weight", 0.0)
    if not _number(cost_weight) or not math.isfinite(cost_weight):
        raise _fail(path, f"cost_weight must be a finite number, got {cost_weight!r}")
    if not isinstance(data.get("description", ""), str):
        raise _fail(path, f"description must be a string, got {data['description']!r}")
    return fields | {"params": _params(path, data["params"]), "cost_weight": float(cost_weight)}


def checked(path: str | Path, build: Callable[[], T]) -> T:
    """`build()`, its one-line refusal prefixed with the suite file's name."""
    try:
        return build()
    except InputError as e:
        if str(e).startswith(f"suite {Path(path)}"):
            raise
        raise _fail(Path(path), str(e)) from None
