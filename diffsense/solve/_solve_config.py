"""Settings and results of the one-parameter continuous solve (`_continuous.solve`)."""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Literal

import jax
import jax.numpy as jnp
import numpy as np

from diffsense.runtime import InputError
from diffsense.solve._steps import SweepPoint

# Gradient evaluations kept back per later continuation level, so an early level cannot spend
# the whole budget.
RESERVE_PER_LEVEL = 3


@dataclasses.dataclass(frozen=True)
class SolveConfig:
    """Settings of the continuous solve (a config section; loadable with diffsense.config).

    Attributes:
        tau_schedule: temperature multipliers of the continuation, largest first; the last is
            the one the soft objective is reported at (1.0 = the sensors' documented defaults).
        xtol_rel: tolerance on r at the last level, relative to the interval width (earlier
            levels use it scaled by tau / tau_last).
        max_evaluations: budget of the continuous solve: objective (soft and hard) plus
            gradient evaluations (20 by default).
        dtype: float type of the outer problem (r, tau).
        method: how the best step's bracket is searched. `secant` (BracketedSecant, warm-started)
            or `bisection` (a downhill walk from the previous level's answer to a sign change,
            then halving): roots of the soft dE^2/dr, a temperature level at a time. `brent`:
            Brent's bounded minimisation on the answer objective's values, no gradient and no
            levels (`_brent`). `auto` (default): `brent` where the answer objective is E_ref
            (a probabilistic detection law; the one-parameter job decides), else `secant`.
        hard_polish: most hard evaluations of the final compass search around r* (0: none);
            it only uses what the budget has left after the soft levels.
        reserve_polish: the soft levels leave `hard_polish` evaluations of the budget unspent, so
            the polish always gets them. Off by default (the speed/accuracy study of
            notebook 02 is measured without it); on radar HFOV 5-60 deg, an interior optimum
            where the continuation otherwise spends the budget, it takes the answer from E_hard
            22.32 to 21.42 m and leaves the main job's answer unchanged (`python -m
            diffsense.optimise --param hfov --interval 5 60 --config
            configs/optimise/reserve_polish.toml`; docs, "The grid-search baseline").

    The defaults: three levels halving tau reach the best dense-grid basin of the rippled
    test objective where tau = 1 alone does not (tests/test_solve_lands.py) and, with the secant,
    fit the budget of 20 evaluations; 1e-3 of 150 deg is 0.15 deg, finer than the
    0.5-deg dense reference grid.
    """

    tau_schedule: tuple[float, ...] = (4.0, 2.0, 1.0)
    xtol_rel: float = 1e-3
    max_evaluations: int = 20
    dtype: Literal["float64", "float32"] = "float64"
    method: Literal["auto", "brent", "secant", "bisection"] = "auto"
    hard_polish: int = 6
    reserve_polish: bool = False

    @property
    def _polish_reserve(self) -> int:
        return self.hard_polish if self.reserve_polish else 0

    def __post_init__(self):
        if self.hard_polish < 0:
            raise InputError(f"hard_polish {self.hard_polish} must be >= 0")
        taus = tuple(self.tau_schedule)
        if not taus or any(not (math.isfinite(t) and t > 0) for t in taus):
            raise InputError(f"tau_schedule {taus} must be positive finite numbers")
        if any(b > a for a, b in zip(taus, taus[1:])):
            raise InputError(f"tau_schedule {taus} must not increase (largest first)")
        if not (0 < self.xtol_rel < 0.5):
            raise InputError(f"xtol_rel {self.xtol_rel} must lie in (0, 0.5)")
        # One gradient for the first level, the reserve of every later one, and the final
        # hard and soft evaluations of the answer.
        least = 1 + RESERVE_PER_LEVEL * (len(taus) - 1) + 2 + self._polish_reserve
        if self.method == "brent":  # no levels: one value is a search
            least = 1
        if self.max_evaluations < least:
            raise InputError(
                f"max_evaluations {self.max_evaluations} is too small for "
                f"{len(taus)} temperature levels{' and the reserved hard polish' if self.reserve_polish else ''} "
                f"(need at least {least})"
            )


@dataclasses.dataclass(frozen=True)
class LevelResult:
    """One temperature level of the continuation.

    Attributes:
        tau: the temperature multiplier.
        r: the soft optimum found at this temperature.
        gradient_evaluations: dE^2/dr evaluations spent on this level.
        bound: -1 / +1 if the minimum is on the bracket's lower / upper edge, 0 inside.
        converged: False if the level ran out of its share of the budget.
    """

    tau: float
    r: float
    gradient_evaluations: int
    bound: int
    converged: bool


@dataclasses.dataclass(frozen=True)
class SolveResult:
    """What the solve found.

    Attributes:
        r_star: the answer (the objective's units).
        E_soft_star: sqrt(E^2_soft(r_star, tau_last)) [m].
        E_hard_star: E_hard(r_star) [m]; never above the best step's E_hard.
        sweep: the stepped sweep (its own evaluations are not in `evaluations`).
        evaluations: {"objective": soft + hard objective evaluations, "gradient": dE^2/dr
            evaluations} of the continuous solve (steps 2-3 of the module docstring).
        on_bound: r_star is an end of the interval (its implicit derivative is zero).
        bracket: (lo, hi) the continuous solve searched in.
        tau_schedule: the temperatures used, largest first.
        levels: per-temperature results.
        notes: human-readable remarks (why the answer is not the soft optimum, budget, ...).
        interval: the whole parameter interval (lo, hi).
        wall_s: {"sweep": s, "solve": s} wall time of the two phases (compilation included).
    """

    r_star: float
    E_soft_star: float
    E_hard_star: float
    sweep: tuple[SweepPoint, ...]
    evaluations: dict[str, int]
    on_bound: bool
    bracket: tuple[float, float]
    tau_schedule: tuple[float, ...]
    levels: tuple[LevelResult, ...]
    notes: tuple[str, ...]
    interval: tuple[float, float]
    wall_s: dict[str, float]

    def to_dict(self) -> dict[str, Any]:
        """A plain, JSON-ready dict of every field."""
        return dataclasses.asdict(self)


def host_array(values: Any, dtype: Any) -> np.ndarray:
    """`values` as a host array of JAX's form of `dtype` (float32 without x64): a compiled
    program takes it as it is, where `jnp.asarray` would be a small program of its own, traced
    and lowered on every run."""
    return np.asarray(values, jax.dtypes.canonicalize_dtype(dtype))


def outer_dtype(name: str) -> Any:
    if name == "float64" and not jax.config.jax_enable_x64:
        raise InputError("the float64 outer solve needs jax_enable_x64 (or set dtype = float32)")
    return jnp.dtype(name)
