"""What a sensor is to diffsense: named differentiable parameters, constants, and `detect`.

A sensor is an equinox Module. Its constants are static fields (hashable, never traced); its
differentiable parameters r are not stored in it: `detect(scene, r, ...)` takes them as a dict
of named scalars (`{"hfov_deg": 45.0}`), so `jax.grad` with respect to any subset of them
works, and a parameter not in r keeps the sensor's default. `Radar` and `Camera` implement it;
a new sensor is one file with a subclass plus a name given to `register`.
"""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Mapping
from typing import Any, ClassVar

import equinox as eqx
from jaxtyping import ArrayLike, Float

from diffsense.runtime import InputError
from diffsense.scene import Scene
from diffsense.sensors._datatypes import Detections
from diffsense.sensors._gates import Mode, check_mode
from diffsense.sensors._measure import KeyOrNoise
from diffsense.sensors._params import ParamSpec
from diffsense.sensors._weather import CLEAR, Weather


class Sensor(eqx.Module):
    """A perception sensor mounted on the ego vehicle (the protocol every sensor implements).

    Subclasses set `kind` (a short name, e.g. "radar") and implement `param_specs`,
    `mount_x_m` and `_detect`. `detect` checks the names in r and fills in the defaults.
    """

    kind: ClassVar[str] = "sensor"

    @abc.abstractmethod
    def param_specs(self) -> tuple[ParamSpec, ...]:
        """The differentiable parameters: name, unit, physical domain and default."""

    @property
    @abc.abstractmethod
    def mount_x_m(self) -> float:
        """How far ahead of the ego's reference point the sensor sits [m]."""

    @abc.abstractmethod
    def _detect(self, scene: Scene, r: dict[str, Any], noise: KeyOrNoise, mode: Mode,
                temperature: Float[ArrayLike, ""], weather: Weather) -> Detections:
        """`detect` with r complete (every parameter named) and checked; a sensor the weather
        does not affect ignores `weather`."""

    def defaults(self) -> dict[str, float]:
        """The default value of every differentiable parameter."""
        return {s.name: s.default for s in self.param_specs()}

    def spec(self, name: str) -> ParamSpec:
        """The spec of parameter `name`; InputError naming the known ones otherwise."""
        for s in self.param_specs():
            if s.name == name:
                return s
        known = ", ".join(s.name for s in self.param_specs())
        raise InputError(f"unknown {self.kind} parameter {name!r} (known: {known})")

    def detect(self, scene: Scene, r: Mapping[str, Any] | None = None, noise: KeyOrNoise | None = None, *,
               mode: Mode = "soft", temperature: Float[ArrayLike, ""] = 1.0, weather: Weather = CLEAR) -> Detections:
        """The sensor looking at `scene` [T, V] with parameters r (defaults for those not given).

        `mode` "soft" gives detection probabilities differentiable in r; "hard" the 0/1
        detections; any other is refused. `noise` is a PRNG key fixing the measurement-noise draws (common random
        numbers across r), or the draws themselves ([2, T, V] from `measurement_noise`).
        `weather` is the scene's (`Weather`; clear by default).
        """
        full = self.defaults()
        for name, value in (r or {}).items():
            self.spec(name)  # refuses an unknown name
            full[name] = value
        if noise is None:
            raise InputError("detect needs a noise key (or the noise draws)")
        # A plugged-in sensor's `_detect` sees only "soft" or "hard": one that tests
        # `mode == "soft"` would otherwise read any other word as hard.
        return self._detect(scene, full, noise, check_mode(mode), temperature, weather)


def params_of(cls: type, r: Mapping[str, Any]) -> Any:
    """The sensor's parameter dataclass `cls` from a complete dict r (values may be traced)."""
    return cls(**{f.name: r[f.name] for f in dataclasses.fields(cls)})
