"""diffsense: differentiable sensor-parameter optimisation for deep-learning perception.

    import jax, diffsense as ds
    problem = ds.Problem(sensor="radar", params={"hfov_deg": (30.0, 180.0)},
                         scenarios=["sc01", "sc03"], variants=4, seed=0)
    E = ds.objective(problem)                                  # pure: jit, grad, vmap
    value, grad = jax.value_and_grad(E)({"hfov_deg": 45.0})    # E [m]; grad is a dict like r
    result = ds.optimise(problem)                              # the main job; result.r_star
    front = ds.pareto(ds.Problem.from_suite("configs/suites/radar_camera_d4.toml"))  # E vs cost

Pipeline (one subpackage per stage, data flowing one way):
    scene -> sensors -> tracks -> predictors -> metrics -> solve -> report
The command-line faces live in `diffsense.cli`.
"""

__version__ = "0.2.0"

from diffsense import predictors, sensors
from diffsense._optimise import objective, optimise
from diffsense._problem import Problem
from diffsense._result import Result
from diffsense._sensitivity import sensitivity
from diffsense._suite_solve import ParetoFront, pareto
from diffsense.errors import InputError
from diffsense.metrics import Objective

__all__ = [
    "InputError", "Objective", "ParetoFront", "Problem", "Result", "__version__", "objective", "optimise",
    "pareto", "predictors", "sensitivity", "sensors",
]
