"""What the box solve is given and what it answers (`box_solve`, `_box.py`): its settings, each
BFGS run and the answer."""

from __future__ import annotations

import dataclasses
import math

from diffsense.runtime import InputError
from diffsense.solve._box_fns import Event


@dataclasses.dataclass(frozen=True)
class BoxConfig:
    """Settings of `box_solve`.

    Attributes:
        samples: size of the coarse hard sample (0: 2 d + 2 for d parameters) where no screen runs.
        screen_points: size of the screened sample where the functions can screen (0: 8 d + 8;
            -1: no screen, the hard sample instead).
        screen_draws: detection draws of a screened value (the box job's screen) [-].
        starts: BFGS runs, from the best sample points [-].
        tau_schedule: temperature multipliers of the continuation, largest first.
        max_steps: BFGS steps per start and temperature (each one soft evaluation) [-].
        max_soft: soft evaluations of the BFGS runs at most [-] (the answer's gradient and each
            start's soft J at the end may add one each).
        rtol, atol: BFGS's Cauchy termination on t [rad] and on the scaled J.
        ftol: a level also stops when J has fallen by less than ftol * |J| over its last 3
            accepted steps (relative; earlier levels use it scaled by tau / tau_last).
        first_step_rad: the first BFGS step's largest move in t [rad].
        check_every: the BFGS iterate is checked on the hard objective (an answer candidate)
            every this many steps as well as at each level's end (0: at the end only).
        bound_tol: distance to a bound, relative to the box, within which a parameter is put on it.
        cost_weight: lambda in J = E + lambda * cost [m per currency unit].
        seed: shifts the Halton sample.
        r_star_axes: the box job also makes r*'s interval per parameter, along its axis through
            r* (`diffsense.study.box_r_star_interval`): up to 25 evaluations of the answer's E per
            parameter, as many again as a long solve on a suite's default problem, so off unless asked.
    """

    samples: int = 0
    screen_points: int = 0
    screen_draws: int = 4
    starts: int = 2
    tau_schedule: tuple[float, ...] = (4.0, 2.0, 1.0)
    max_steps: int = 30
    max_soft: int = 400
    rtol: float = 1e-6
    atol: float = 1e-6
    ftol: float = 1e-4
    first_step_rad: float = 0.5
    check_every: int = 3
    bound_tol: float = 1e-6
    cost_weight: float = 0.0
    seed: int = 0
    r_star_axes: bool = False

    def __post_init__(self):
        taus = tuple(float(t) for t in self.tau_schedule)
        if not taus or not all(math.isfinite(t) and t > 0 for t in taus) or list(taus) != sorted(taus, reverse=True):
            raise InputError(f"tau_schedule {taus} must be positive numbers, largest first")
        for name in ("samples", "starts", "max_steps", "max_soft", "check_every"):
            if getattr(self, name) < 0:
                raise InputError(f"{name} must be >= 0, got {getattr(self, name)}")
        if self.screen_points < -1:
            raise InputError(f"screen_points must be >= -1 (-1: no screen), got {self.screen_points}")
        if self.screen_draws < 2:
            raise InputError(f"screen_draws must be >= 2, got {self.screen_draws}")
        if not (self.cost_weight >= 0 and math.isfinite(self.cost_weight)):
            raise InputError(f"cost_weight must be a finite number >= 0, got {self.cost_weight}")


@dataclasses.dataclass(frozen=True)
class StartResult:
    """One BFGS run: where it began and ended, J there (soft at the last level, hard), steps per level."""

    x0: dict[str, float]
    x: dict[str, float]
    J_soft: float
    J_hard: float
    steps: tuple[int, ...]


@dataclasses.dataclass(frozen=True)
class BoxResult:
    """The answer of `box_solve`.

    Attributes:
        x_star: r*, {name: value} in each parameter's unit.
        J_star: E_hard + cost_weight * cost at r* (what the answer was chosen on).
        E_hard, E_soft: E [m] at r*, hard and soft (at the last temperature). "Hard" is the
            functions' `e_hard`: E_ref when they judge on it (a probabilistic detection law).
        cost: cost(r*) [currency] (0 without a cost model).
        gradient: dJ_soft/dx at r* per parameter [m per unit] (at the last temperature).
        gradient_E: dE_soft/dx at r* per parameter [m per unit].
        on_bound: per parameter "lower", "upper" or "" (interior).
        source: "start k tau T" (the k-th BFGS run's answer at temperature T), "start k tau T step"
            (an iterate checked on the way) or "sample".
        starts: every BFGS run.
        counts: distinct soft (value and gradient) and hard evaluations the solve made, and
            "screen", the points screened, where a screen ran.
        history: every evaluation in order (`BoxFunctions.history` since the solve began).
    """

    names: tuple[str, ...]
    bounds: dict[str, tuple[float, float]]
    x_star: dict[str, float]
    J_star: float
    E_hard: float
    E_soft: float
    cost: float
    gradient: dict[str, float]
    gradient_E: dict[str, float]
    on_bound: dict[str, str]
    source: str
    starts: tuple[StartResult, ...]
    counts: dict[str, int]
    history: tuple[Event, ...]
    tau_schedule: tuple[float, ...]
    cost_weight: float
