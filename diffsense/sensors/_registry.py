"""The sensors known by name: `register` a factory, `make_sensor` builds one (or a fused suite).

It sits above every sensor and the suite: the built-in radar and camera are registered here.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from diffsense.runtime import InputError
from diffsense.sensors._camera import Camera
from diffsense.sensors._fusion import Suite
from diffsense.sensors._radar import Radar
from diffsense.sensors._sensor import Sensor

_REGISTRY: dict[str, Callable[[], Sensor]] = {}


def register(name: str, factory: Callable[..., Sensor]) -> None:
    """Make a sensor available by name (`ds.Problem(sensor=name)`): `factory()` builds it with
    its shipped constants, `factory(path, profile)` from a user TOML and a profile (a factory
    that takes no arguments serves the default profile only). The name is letters, digits and
    '_', at least one of them a letter or digit."""
    if not name or not name.replace("_", "").isalnum():
        raise InputError(f"a sensor name is letters, digits and '_', with a letter or digit, got {name!r}")
    _REGISTRY[name] = factory


def sensor_names() -> tuple[str, ...]:
    """The names of the registered sensors."""
    return tuple(_REGISTRY)


def make_sensor(sensor: str | Sensor | Sequence[str | Sensor], config: str | None = None,
                profile: str = "physical") -> Sensor:
    """The registered sensor `name` of `profile`, with the constants of the TOML at `config`
    replacing the profile's (a Sensor is returned as is, and then takes neither). A sequence of
    them is a `Suite` (fused; parameters named "radar.hfov_deg"); a suite takes no `config`."""
    if isinstance(sensor, (list, tuple)):
        if config is not None:
            raise InputError("a sensor config applies to one sensor: give a suite's members as Sensor objects instead")
        if len(sensor) == 1:
            return make_sensor(sensor[0], None, profile)
        return Suite([make_sensor(s, None, profile) for s in sensor])
    if isinstance(sensor, Sensor):
        if config is not None or profile != "physical":
            raise InputError("a Sensor object carries its own constants: give no sensor config or profile with it")
        return sensor
    if sensor not in _REGISTRY:
        raise InputError(f"unknown sensor {sensor!r} (known: {', '.join(_REGISTRY)})")
    if config is None and profile == "physical":
        return _REGISTRY[sensor]()
    return _REGISTRY[sensor](config, profile)


register("radar", Radar.from_toml)
register("camera", Camera.from_toml)
