"""diffsense: differentiable sensor-parameter optimisation for deep-learning perception.

    import jax, diffsense as ds
    problem = ds.Problem(sensor="radar", params={"hfov_deg": (30.0, 180.0)},
                         scenarios=["sc01", "sc03"], variants=4, seed=0)
    E = ds.objective(problem)                                  # pure: jit, grad, vmap
    value, grad = jax.value_and_grad(E)({"hfov_deg": 45.0})    # E [m]; grad is a dict like r
    result = ds.optimise(problem)                              # the main job; result.r_star
    front = ds.pareto(ds.Problem.from_suite("configs/suites/radar_camera_d4.toml"))  # E vs cost

Packages, data flowing one way (docs/architecture.md):
    scene -> sensors -> tracks -> predictors -> metrics -> solve -> study -> report -> cli
with `runtime` (and `config`) beneath them all.
"""

import importlib
import importlib.util
import os
import signal
import sys
import types
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from diffsense import predictors, sensors
    from diffsense.metrics import Objective
    from diffsense.runtime import InputError, __version__
    from diffsense.study import ParetoFront, Problem, Result, objective, optimise, pareto, sensitivity

# Each public name -> the package it comes from. They are imported on first use (PEP 562), so
# `import diffsense` costs milliseconds and a command installs its signal handlers (below)
# before JAX is imported, which takes seconds.
_EXPORTS = {
    "InputError": "diffsense.runtime", "__version__": "diffsense.runtime", "Objective": "diffsense.metrics",
    **dict.fromkeys(["ParetoFront", "Problem", "Result", "objective", "optimise", "pareto", "sensitivity"],
                    "diffsense.study"),
}

__all__ = [
    "InputError", "Objective", "ParetoFront", "Problem", "Result", "__version__", "objective", "optimise",
    "pareto", "predictors", "sensitivity", "sensors",
]


def __getattr__(name: str) -> object:
    """A public name, or a stage package (`ds.metrics`), imported when first asked for."""
    if name in _EXPORTS:
        value = getattr(importlib.import_module(_EXPORTS[name]), name)
    elif not name.startswith("_") and importlib.util.find_spec(f"{__name__}.{name}") is not None:
        value = importlib.import_module(f"{__name__}.{name}")
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    setattr(sys.modules[__name__], name, value)
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


class _Package(types.ModuleType):
    """This package, with one rule: importing the `python -m diffsense.optimise` module (the main
    job's command line) leaves `diffsense.optimise` the function. Python binds a submodule to its
    parent's attribute of the same name once it is imported; that binding is refused here."""

    def __setattr__(self, name: str, value: object) -> None:
        if name == "optimise" and isinstance(value, types.ModuleType):
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package

_CONSOLE_SCRIPTS = ("diffsense", "diffsense-optimise")  # pyproject.toml's [project.scripts]
_ENDINGS = {signal.SIGINT: ("interrupted", 130), signal.SIGTERM: ("terminated", 143)}


def _a_command_starts() -> bool:
    """Whether this process is a diffsense command: `python -m diffsense.X` (the interpreter sets
    argv[0] to "-m" while it imports the packages of the module it runs) or a console script."""
    if sys.argv[:1] == ["-m"]:
        args = list(getattr(sys, "orig_argv", []))
        for flag, following in zip(args, [*args[1:], ""]):
            if flag.startswith("-m"):
                return (following if flag == "-m" else flag[2:]).startswith(f"{__name__}.")
        return False
    return bool(sys.argv) and os.path.basename(sys.argv[0]) in _CONSOLE_SCRIPTS


def _end_at_once(signum: int, _frame: object) -> None:
    """Until a command's `run` (diffsense.cli) takes over, nothing is written: end with the line."""
    line, code = _ENDINGS[signum]
    os.write(2, f"{line}\n".encode())
    os._exit(code)


# A command handles SIGINT and SIGTERM from its first moment, before JAX is imported: this module
# runs before any other of the package (`python -m diffsense.scene` imports the stage before its
# __main__), so they are installed here, in a command's process only; a library user's process
# keeps its own. An inherited SIG_IGN is overridden too: a signal sent to a run is a request to
# stop it, whether or not a shell started the run in the background (docs/cli.md).
if _a_command_starts():
    for _signum in _ENDINGS:
        signal.signal(_signum, _end_at_once)
