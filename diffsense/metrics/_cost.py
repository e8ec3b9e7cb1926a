"""The sensor cost model: cost(r) of a sensor or suite, smooth in every parameter it charges for.

    model = load_costs()                          # configs/costs.toml (or a user TOML)
    cost = make_cost(model, suite)                # cost(r) [currency], r named as the sensor names them
    member_costs(model, suite, r)                 # {"front_radar": 85.0, "corner_left": 96.2, ...}
    J = E(r) + cost_weight * cost(r)              # the objective of a cost-aware problem

cost = sum over a suite's members of their kind's base + sum of terms (two radars cost two radars,
each at its own parameters), each term either
    "power": coefficient * (value / reference) ^ exponent
    "db":    coefficient * 10 ^ (exponent * (value - reference) / 10)
so a term equals its coefficient at its reference value. Both forms are smooth and positive,
and increasing in the value when the exponent is positive. The shipped figures and what each
assumes are in `configs/costs.toml`; parameters without a term cost nothing.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Literal

import jax.numpy as jnp
from jaxtyping import Array, Float

from diffsense import config as cfgio
from diffsense.runtime import InputError
from diffsense.sensors import Sensor

# (value / reference) is floored here before its log: a "power" term with a negative exponent
# would be infinite at value 0, which no parameter domain reaches but a traced value could.
_RATIO_FLOOR = 1e-12


@dataclasses.dataclass(frozen=True)
class CostTerm:
    """One cost term of a sensor parameter (module docstring for the forms).

    Attributes:
        param: the sensor's parameter name ("range_m").
        form: "power" or "db".
        coefficient: the term's cost at `reference` [currency].
        reference: the value at which the term costs `coefficient`, in the parameter's unit.
        exponent: how fast the term grows [-] (negative: falls as the value grows).
        note: what the term stands for and what it assumes.
    """

    param: str
    form: Literal["power", "db"]
    coefficient: float
    reference: float
    exponent: float
    note: str = ""

    def __post_init__(self):
        if self.coefficient < 0:
            raise InputError(f"cost term {self.param}: coefficient must be >= 0, got {self.coefficient:g}")
        if self.form == "power" and not self.reference > 0:
            raise InputError(f"cost term {self.param}: a power term's reference must be > 0, got {self.reference:g}")

    def __call__(self, value: Float[Array, ""]) -> Float[Array, ""]:
        """The term's cost at `value` [currency]."""
        if self.form == "power":
            ratio = jnp.maximum(value / self.reference, _RATIO_FLOOR)
            return self.coefficient * jnp.exp(self.exponent * jnp.log(ratio))
        return self.coefficient * jnp.exp(self.exponent * (value - self.reference) * (math.log(10.0) / 10.0))


@dataclasses.dataclass(frozen=True)
class SensorCost:
    """The cost of one kind of sensor: a base price and its parameters' terms [currency]."""

    base: float
    terms: tuple[CostTerm, ...] = ()
    note: str = ""

    def __post_init__(self):
        if self.base < 0:
            raise InputError(f"a sensor's base cost must be >= 0, got {self.base:g}")
        params = [t.param for t in self.terms]
        if len(set(params)) != len(params):
            raise InputError(f"cost term named twice: {sorted(p for p in params if params.count(p) > 1)[0]}")


@dataclasses.dataclass(frozen=True)
class CostModel:
    """Costs per sensor kind ("radar", "camera") in one `currency`."""

    currency: str
    sensors: dict[str, SensorCost]


def load_costs(path: str | Path | None = None) -> CostModel:
    """The cost model of `configs/costs.toml`, or of the TOML at `path` (every key given)."""
    if path is None:
        return cfgio.load_default(CostModel, "costs.toml")
    return cfgio.load(CostModel, path)


def _members(sensor: Sensor) -> list[tuple[str, Sensor]]:
    """(prefix, sensor) pairs: "" for a lone sensor, "<name>." for each member of a suite."""
    members = getattr(sensor, "members", None)
    if members is None:
        return [("", sensor)]
    return [(f"{n}.", m) for n, m in zip(sensor.names, members)]


def _checked(model: CostModel, sensor: Sensor) -> list[tuple[str, Sensor, SensorCost]]:
    out = []
    for prefix, member in _members(sensor):
        if member.kind not in model.sensors:
            raise InputError(f"no cost for sensor {member.kind!r} in the cost model "
                             f"(known: {', '.join(model.sensors)})")
        entry = model.sensors[member.kind]
        for term in entry.terms:
            member.spec(term.param)  # refuses a term on a parameter the sensor does not have
        out.append((prefix, member, entry))
    return out


def make_cost(model: CostModel, sensor: Sensor) -> Callable[[Mapping[str, Any]], Float[Array, ""]]:
    """cost(r) [model.currency] of `sensor` (a lone sensor or a suite), pure and differentiable.

    r names parameters as `sensor` does ("hfov_deg" for a radar, "radar.hfov_deg" in a suite);
    those it leaves out keep the sensor's defaults (and are charged at them).
    """
    entries = _checked(model, sensor)
    defaults = sensor.defaults()

    def cost(r: Mapping[str, Any]) -> Float[Array, ""]:
        for name in r:
            sensor.spec(name)
        full = defaults | dict(r)
        total = 0.0
        for prefix, _, entry in entries:
            total = total + entry.base
            for term in entry.terms:
                total = total + term(jnp.asarray(full[prefix + term.param]))
        return jnp.asarray(total)

    return cost


def cost_breakdown(model: CostModel, sensor: Sensor, r: Mapping[str, Any]) -> dict[str, float]:
    """Each base and term of cost(r) [currency]: {"radar.base": 45.0, "radar.range_m": 15.0, ...}."""
    full = sensor.defaults() | dict(r)
    out: dict[str, float] = {}
    for prefix, member, entry in _checked(model, sensor):
        label = prefix or f"{member.kind}."
        out[label + "base"] = float(entry.base)
        for term in entry.terms:
            out[label + term.param] = float(term(jnp.asarray(full[prefix + term.param])))
    return out


def member_costs(model: CostModel, sensor: Sensor, r: Mapping[str, Any]) -> dict[str, float]:
    """cost(r) of each member of a suite [currency], by member name, in the suite's order
    ({"front_radar": 85.0, "corner_left": 92.5}); a lone sensor's under its kind. They sum to
    `make_cost(model, sensor)(r)`; parameters r leaves out are charged at their defaults."""
    full = sensor.defaults() | dict(r)
    out: dict[str, float] = {}
    for prefix, member, entry in _checked(model, sensor):
        name = prefix[:-1] if prefix else member.kind
        out[name] = float(entry.base) + sum(float(t(jnp.asarray(full[prefix + t.param]))) for t in entry.terms)
    return out
