"""A suite's named members: `Member` (name, kind, constants, mounting) and the mapping form a
user gives them in (`ds.Problem(sensor={...})`, a suite file's `[members.NAME]` tables).

    sensor = {"front_radar": "radar",
              "corner_left": {"kind": "radar", "sensor_config": "radar_swerling1.toml",
                              "yaw_deg": 45.0, "mount_y_m": 0.8, "envelope": {"yaw_deg": (30, 80)}}}
    members = named_members(sensor)          # (Member("front_radar", "radar"), Member("corner_left", ...))
    suite = build_suite(members, "physical") # a `diffsense.sensors.Suite` named by them

A member's parameters are qualified by its name ("corner_left.yaw_deg"); two members may be of
one kind. Its mounting defaults (`yaw_deg`, `mount_x_m`, `mount_y_m`) replace its sensor's, and
its envelope narrows the global one (`diffsense.sensors.MOUNT_DOMAINS`) for a solve's bounds.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from diffsense.runtime import InputError
from diffsense.sensors import MOUNT_NAMES, Mounting, Sensor, Suite, make_sensor

MEMBER_KEYS = ("kind", "sensor_config", *MOUNT_NAMES, "envelope")


@dataclasses.dataclass(frozen=True)
class Member:
    """One named member of a suite.

    Attributes:
        name: the prefix of its parameters ("front_radar" -> "front_radar.hfov_deg"): letters,
            digits and '_'.
        kind: a registered sensor name ("radar", "camera") or a `diffsense.sensors.Sensor`.
        sensor_config: a TOML of constants (any subset) replacing its profile's; None: the
            profile's. Not for a Sensor object, which carries its own.
        mounting: its mounting defaults and envelope (`diffsense.sensors.Mounting`).
    """

    name: str
    kind: str | Sensor
    sensor_config: str | None = None
    mounting: Mounting = dataclasses.field(default_factory=Mounting)

    def __post_init__(self):
        if not (isinstance(self.name, str) and self.name and self.name.replace("_", "").isalnum()):
            raise InputError(f"a member's name is letters, digits and '_', got {self.name!r}")
        if not (isinstance(self.kind, Sensor) or (isinstance(self.kind, str) and self.kind)):
            raise InputError(f"member {self.name}: kind must be a sensor name (e.g. \"radar\") or a Sensor, "
                             f"got {self.kind!r}")
        if self.sensor_config is not None:
            if isinstance(self.kind, Sensor):
                raise InputError(f"member {self.name}: a Sensor object carries its own constants: give no sensor_config")
            if not isinstance(self.sensor_config, (str, Path)):
                raise InputError(f"member {self.name}: sensor_config must be a TOML path, got {self.sensor_config!r}")
            object.__setattr__(self, "sensor_config", str(self.sensor_config))
        if not isinstance(self.mounting, Mounting):
            raise InputError(f"member {self.name}: mounting must be a diffsense.sensors.Mounting")

    def as_plain(self) -> dict[str, Any]:
        """The member in the mapping form (result.json's config): kind, sensor_config, mounting."""
        out: dict[str, Any] = {"kind": self.kind if isinstance(self.kind, str) else type(self.kind).__name__}
        if self.sensor_config is not None:
            out["sensor_config"] = self.sensor_config
        out.update(dict(self.mounting.defaults))
        if self.mounting.envelope:
            out["envelope"] = {n: [lo, hi] for n, lo, hi in self.mounting.envelope}
        return out


def _member(name: Any, value: Any) -> Member:
    """A Member from one entry of the mapping form: a kind, or a table of MEMBER_KEYS."""
    if not isinstance(name, str):
        raise InputError(f"a member's name is a string, got {name!r}")
    if isinstance(value, Member):
        if value.name != name:
            raise InputError(f"member {name} is given as Member {value.name!r}: give it under its own name")
        return value
    if not isinstance(value, Mapping):
        return Member(name, value)
    unknown = [k for k in value if k not in MEMBER_KEYS]
    if unknown:
        raise InputError(f"member {name}: unknown key {unknown[0]!r} (known: {', '.join(MEMBER_KEYS)})")
    if "kind" not in value:
        raise InputError(f"member {name}: no kind (e.g. kind = \"radar\")")
    envelope = value.get("envelope", {})
    if not isinstance(envelope, Mapping):
        raise InputError(f"member {name}: envelope must be a table of mounting parameter = [LO, HI], got {envelope!r}")
    try:
        mounting = Mounting(defaults={k: value[k] for k in MOUNT_NAMES if k in value}, envelope=envelope)
    except InputError as e:
        raise InputError(f"member {name}: {e}") from None
    return Member(name, value["kind"], value.get("sensor_config"), mounting)


def named_members(sensor: Mapping[str, Any] | Sequence[Member]) -> tuple[Member, ...]:
    """The members of the mapping form {name: kind or table} (or a sequence of `Member`s), in
    order; InputError (one line) for a name given twice, a missing kind, an unknown key, ..."""
    entries = list(sensor.items()) if isinstance(sensor, Mapping) else [(getattr(m, "name", None), m) for m in sensor]
    if not entries:
        raise InputError("a suite needs at least one member")
    members = tuple(_member(name, value) for name, value in entries)
    names = [m.name for m in members]
    twice = sorted(n for n in set(names) if names.count(n) > 1)
    if twice:
        raise InputError(f"suite member named twice: {twice[0]}")
    return members


def is_named(sensor: Any) -> bool:
    """Whether `sensor` gives named members: a mapping, or a non-empty sequence of `Member`s."""
    if isinstance(sensor, Mapping):
        return True
    return isinstance(sensor, (list, tuple)) and bool(sensor) and all(isinstance(m, Member) for m in sensor)


def build_suite(members: Sequence[Member], profile: str) -> Suite:
    """The fused `Suite` of `members`, each built from its kind, profile and sensor_config; a
    refusal names the member."""
    sensors = []
    for m in members:
        try:
            sensors.append(make_sensor(m.kind, m.sensor_config, profile))  # a Sensor object: the physical profile only
        except InputError as e:
            raise InputError(f"member {m.name}: {e}") from None
    return Suite(sensors, names=[m.name for m in members], mountings=[m.mounting for m in members])
