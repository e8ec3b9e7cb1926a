"""Solve: the stepped sweep, the continuous argmin of E(r), dr*/dtheta, the dense baseline.

    sweep, default_steps         the paper's discrete grid, hard and soft (the cross-check)
    solve, SolveConfig           bracket from the best step, optimistix refinement with
                                 temperature continuation, answer chosen on the hard objective
    argmin, argmin_derivative    dr*/dtheta by the implicit function theorem (optimistix
                                 ImplicitAdjoint, or the explicit formula); zero on a bound
    dense_grid_search, basin_check   the brute-force baseline and its basin cross-check
    brent_minimise, brent_solve  Brent's bounded minimisation on values; the sweep + Brent search
    hard_grid_solve              the hard estimator's search (no gradient): sweep + inner grid
    Evaluator                    a pure objective compiled once, memoised and counted
    box_solve, BoxConfig         many parameters in a box: Halton sample (or a batched screen), BFGS
                                 per temperature, iterates checked on the hard objective
    pareto_sweep, pareto_front   one box solve per cost weight; which (E, cost) are Pareto-optimal
    near_optimal, explain        the answer's near-optimal set and its flags, in words

Objective protocol: `e2_soft(r, tau) -> E^2 [m^2]` (jax-differentiable in r; tau = 1 is the
sensors' documented temperatures, larger is smoother) and `e_hard(r) -> E [m]`, both pure.
"""

from diffsense.solve._answer import explain, near_optimal
from diffsense.solve._box import box_solve
from diffsense.solve._box_config import BoxConfig, BoxResult
from diffsense.solve._box_fns import BoxFunctions
from diffsense.solve._bracketed import BracketedSecant
from diffsense.solve._brent import brent_minimise, brent_solve
from diffsense.solve._continuous import LevelResult, SolveConfig, SolveResult, solve
from diffsense.solve._dense import DenseGrid, basin_check, dense_grid_search
from diffsense.solve._evaluator import Evaluator
from diffsense.solve._hard_grid import hard_grid_solve
from diffsense.solve._implicit import argmin, argmin_derivative
from diffsense.solve._pareto import _pareto_front as pareto_front
from diffsense.solve._pareto import pareto_sweep
from diffsense.solve._steps import (
    PAPER_HFOV_STEPS_DEG,
    SweepPoint,
    best_step,
    bracket_around,
    check_interval,
    check_steps,
    default_steps,
    sweep,
)

__all__ = [
    "PAPER_HFOV_STEPS_DEG",
    "BoxConfig",
    "BoxFunctions",
    "BoxResult",
    "BracketedSecant",
    "DenseGrid",
    "Evaluator",
    "LevelResult",
    "SolveConfig",
    "SolveResult",
    "SweepPoint",
    "argmin",
    "explain",
    "near_optimal",
    "argmin_derivative",
    "basin_check",
    "box_solve",
    "brent_minimise",
    "brent_solve",
    "pareto_front",
    "pareto_sweep",
    "best_step",
    "bracket_around",
    "check_interval",
    "check_steps",
    "default_steps",
    "dense_grid_search",
    "hard_grid_solve",
    "solve",
    "sweep",
]
