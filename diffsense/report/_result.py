"""result.json: the machine-readable record of one optimisation run.

Schema (JSON-schema-like; every key is always present, numbers are JSON numbers or null when
not finite):

    {
      "param":        string   the sensor parameter optimised, e.g. "hfov"
      "interval":     [lo, hi] numbers, the search interval, in `r_unit`
      "r_unit":       string   unit of every r in this file (SI: "rad", "m", "dB", ...)
      "sensor":       string   "radar" | "camera"
      "r_star":       number   the answer r*
      "E_soft_star":  number   E_RMSE at r* with soft detections at the final temperature [m]
      "E_hard_star":  number   E_RMSE at r* with hard detections [m]; <= every sweep E_hard
      "sweep":        [ {"r": number, "E_hard": number [m], "E_soft": number [m]}, ... ]
                               the stepped sweep, ascending r
      "evaluations":  {"objective": int, "gradient": int}  evaluations of the continuous solve
                               (soft and hard objective values; dE^2/dr), the sweep excluded
      "wall_s":       {"compile": number, "run": number}  wall time [s]
      "on_bound":     bool     r* is an end of the interval (then dr*/dtheta = 0)
      "bracket":      [lo, hi] the neighbouring steps of the best step, where r* was sought
      "tau_schedule": [number, ...] temperature multipliers of the continuation, largest first
      "notes":        [string, ...] why the answer is what it is, when that needs saying
      "config":       object   the full configuration of the run (plain JSON)
      "versions":     {"python", "jax", "jaxlib", "flax", "optax", "optimistix", "numpy",
                       "diffsense": string}
      ...                      any `extra` keys the caller adds (never replacing the above)
    }
"""

from __future__ import annotations

import importlib.metadata
import math
import os
import platform
from collections.abc import Mapping
from typing import Any

import diffsense
from diffsense._io import write_json
from diffsense.solve import SolveResult

RESULT_KEYS = (
    "param",
    "interval",
    "r_unit",
    "sensor",
    "r_star",
    "E_soft_star",
    "E_hard_star",
    "sweep",
    "evaluations",
    "wall_s",
    "on_bound",
    "bracket",
    "tau_schedule",
    "notes",
    "config",
    "versions",
)
_PACKAGES = ("jax", "jaxlib", "flax", "optax", "optimistix", "numpy")


def versions() -> dict[str, str]:
    """Versions of Python, the numerical packages and diffsense."""
    out = {"python": platform.python_version()}
    for name in _PACKAGES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "not installed"
    out["diffsense"] = diffsense.__version__
    return out


def _plain(value: Any) -> Any:
    """JSON-ready: tuples to lists, numpy scalars to Python, non-finite floats to None."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "tolist"):  # numpy / jax arrays and scalars
        return _plain(value.tolist())
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if value is None or isinstance(value, (bool, int, str)):
        return value
    raise TypeError(f"cannot write {type(value).__name__} to JSON")


def result_dict(
    result: SolveResult,
    *,
    param: str,
    sensor: str,
    r_unit: str,
    wall_s: Mapping[str, float],
    config: Mapping[str, Any],
    extra: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The result.json content (module docstring) for one solve.

    Args:
        result: the solve's result.
        param, sensor, r_unit: what was optimised, on which sensor, in which unit.
        wall_s: {"compile": s, "run": s}.
        config: the full run configuration as a plain dict (diffsense.config.to_dict).
        extra: more keys to record (must not collide with the schema's).
    """
    missing = {"compile", "run"} - set(wall_s)
    if missing:
        raise ValueError(f"wall_s lacks {sorted(missing)}")
    out = {
        "param": param,
        "interval": list(result.interval),
        "r_unit": r_unit,
        "sensor": sensor,
        "r_star": result.r_star,
        "E_soft_star": result.E_soft_star,
        "E_hard_star": result.E_hard_star,
        "sweep": [{"r": p.r, "E_hard": p.E_hard, "E_soft": p.E_soft} for p in result.sweep],
        "evaluations": {k: result.evaluations[k] for k in ("objective", "gradient")},
        "wall_s": {"compile": wall_s["compile"], "run": wall_s["run"]},
        "on_bound": result.on_bound,
        "bracket": list(result.bracket),
        "tau_schedule": list(result.tau_schedule),
        "notes": list(result.notes),
        "config": dict(config),
        "versions": versions(),
    }
    for key, value in (extra or {}).items():
        if key in out:
            raise ValueError(f"extra key {key!r} would replace a result.json key")
        out[key] = value
    return _plain(out)


def write_result_json(path: str | os.PathLike[str], content: Mapping[str, Any]) -> None:
    """Write a result dict (from `result_dict`) to `path` atomically."""
    missing = [k for k in RESULT_KEYS if k not in content]
    if missing:
        raise ValueError(f"result.json content lacks {missing}")
    write_json(path, _plain(content))
