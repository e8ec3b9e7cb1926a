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

import sys
import types

from diffsense import predictors, sensors
from diffsense.metrics import Objective
from diffsense.runtime import InputError, __version__
from diffsense.study import (
    ParetoFront,
    Problem,
    Result,
    objective,
    optimise,
    pareto,
    sensitivity,
)

__all__ = [
    "InputError", "Objective", "ParetoFront", "Problem", "Result", "__version__", "objective", "optimise",
    "pareto", "predictors", "sensitivity", "sensors",
]


class _Package(types.ModuleType):
    """This package, with one rule: importing the `python -m diffsense.optimise` module (the main
    job's command line) leaves `diffsense.optimise` the function. Python binds a submodule to its
    parent's attribute of the same name once it is imported; that binding is refused here."""

    def __setattr__(self, name: str, value: object) -> None:
        if name == "optimise" and isinstance(value, types.ModuleType):
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
