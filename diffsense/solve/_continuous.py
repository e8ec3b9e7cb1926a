"""The continuous solve: the best r over an interval, refined from the stepped sweep.

Strategy:
1. the sweep's best step on the HARD objective gives a bracket: its neighbouring steps;
2. inside the bracket, the minimum of the SOFT objective E^2(r, tau) is found as the root of
   dE^2/dr (the optimistix solver `BracketedSecant`, or bisection), for each temperature of a
   continuation schedule, largest first, each level warm-started from the one before;
3. the final answer is chosen by the HARD objective: the soft optimum is kept when it is at
   least as good as the best step, otherwise the other candidates (earlier levels' optima, the
   best step itself) are compared and `notes` says why the answer is not the soft optimum. So
   E_hard(r*) <= min over steps of E_hard always holds;
4. a hard polish: a compass search on E_hard around that answer with the evaluations left in
   the budget (at most `SolveConfig.hard_polish`; `reserve_polish` keeps them back from step 2). The soft objective cannot see the hard one's
   fine structure (a vehicle toggling in and out of the FOV at one instant moves E_hard by
   centimetres over a fraction of a degree); a few hard probes near r* settle it, and a probe is
   only accepted when it is strictly better, so this step never makes the answer worse.

E^2 is optimised (the gradient of sqrt is NaN at 0); E = sqrt(E^2) is reported. Every objective
and gradient evaluation of step 2-3 is counted against `SolveConfig.max_evaluations`.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from typing import Any, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from diffsense.errors import InputError
from diffsense.solve._bracketed import BracketedSecant
from diffsense.solve._steps import (
    SweepPoint,
    best_step,
    bracket_around,
    check_interval,
    check_steps,
    default_steps,
    sweep,
)

# Gradient evaluations kept back per later continuation level, so an early level cannot spend
# the whole budget.
_RESERVE_PER_LEVEL = 3


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
        method: `secant` (BracketedSecant, warm-started) or `bisection` (a downhill walk from
            the previous level's answer to a sign change, then halving).
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
    test objective where tau = 1 alone does not (tests/test_solve.py) and, with the secant,
    fit the budget of 20 evaluations; 1e-3 of 150 deg is 0.15 deg, finer than the
    0.5-deg dense reference grid.
    """

    tau_schedule: tuple[float, ...] = (4.0, 2.0, 1.0)
    xtol_rel: float = 1e-3
    max_evaluations: int = 20
    dtype: Literal["float64", "float32"] = "float64"
    method: Literal["secant", "bisection"] = "secant"
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
        least = 1 + _RESERVE_PER_LEVEL * (len(taus) - 1) + 2 + self._polish_reserve
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


def _outer_dtype(name: str) -> Any:
    if name == "float64" and not jax.config.jax_enable_x64:
        raise InputError("the float64 outer solve needs jax_enable_x64 (or set dtype = float32)")
    return jnp.dtype(name)


def _e_from_e2(e2: Any) -> float:
    return math.sqrt(max(float(e2), 0.0))


class _Counted:
    """Objective and gradient callables that count their evaluations (Python side)."""

    def __init__(self, e2_soft, e_hard, dtype, value_and_grad=None):
        self.dtype = dtype
        self._e2 = e2_soft
        self._e_hard = e_hard
        self._grad = jax.jit(jax.grad(e2_soft))
        if value_and_grad is not None:  # a host objective: compiled and memoised elsewhere
            self._e2 = lambda r, tau: value_and_grad(float(r), float(tau))[0]
            self._grad = lambda r, tau: value_and_grad(float(r), float(tau))[1]
        self.objective = 0
        self.gradient = 0

    def as_r(self, r: float) -> jax.Array:
        return jnp.asarray(r, self.dtype)

    def on_grid(self, r: float) -> float:
        """r rounded to the nearest number of the solve's dtype (float32 solves stay float32)."""
        return float(np.asarray(r, np.dtype(self.dtype)))

    def e2(self, r: float, tau: float) -> float:
        self.objective += 1
        return float(self._e2(self.as_r(r), self.as_r(tau)))

    def hard(self, r: float) -> float:
        self.objective += 1
        return float(self._e_hard(self.as_r(r)))

    def grad(self, r: float, tau: float) -> float:
        self.gradient += 1
        return float(self._grad(self.as_r(r), self.as_r(tau)))


_SECANT = BracketedSecant(rtol=0.0, atol=0.0)


@eqx.filter_jit
def _secant_init(y, options):
    return _SECANT.init(None, y, None, options, jax.ShapeDtypeStruct((), y.dtype), None, frozenset())


@eqx.filter_jit
def _secant_step(g, y, options, state):
    # The solver's step evaluates g at y exactly once: hand it the value measured outside.
    y, state, _ = _SECANT.step(lambda y_, args: (g, None), y, None, options, state, frozenset())
    return y, state


def _level_secant(counted, y0, tau, lower, upper, probe, tol, max_steps, budget):
    """One temperature level: optimistix's init/step/terminate loop of `BracketedSecant`, driven
    from Python so that each gradient comes from the objective's own compiled program (no host
    callback inside a compiled loop: every program stays in the persistent compilation cache).
    The options are traced values: the levels share two small compiled programs."""
    options = dict(
        lower=counted.as_r(lower),
        upper=counted.as_r(upper),
        probe=counted.as_r(probe),
        xtol=counted.as_r(tol),
    )  # the Python loop below ends a level at its share: no max_evaluations option to read
    y = counted.as_r(y0)
    state = _secant_init(y, options)
    n = 0
    while n < budget and not (bool(state.done) or n >= max_steps):
        g = jnp.asarray(counted.grad(float(y), tau), counted.dtype)
        y, state = _secant_step(g, y, options, state)
        n += 1
    if bool(state.nonfinite):
        raise FloatingPointError(f"dE^2/dr is not finite near r={float(y)} (tau={tau})")
    return float(y), n, int(state.bound), bool(state.done)


def _hard_polish(counted, r, e_hard, lower, upper, probes, min_step):
    """Compass search on E_hard from (r, e_hard) inside [lower, upper]: probe r + step, then
    r - step, move on a strict improvement, halve the step when neither side improves. Spends
    at most `probes` hard evaluations (probes outside the bracket cost nothing); returns the best
    (r, E_hard) seen."""
    step = (upper - lower) / 16.0
    while probes > 0 and step >= min_step:
        moved = False
        for candidate in (r + step, r - step):
            if probes == 0 or not lower <= candidate <= upper:
                continue
            probes -= 1
            e = counted.hard(candidate)
            if e < e_hard:
                r, e_hard, moved = candidate, e, True
                break
        if not moved:
            step *= 0.5
    return r, e_hard


def _checked_grad(counted, r, tau):
    value = counted.grad(r, tau)
    if not math.isfinite(value):
        raise FloatingPointError(f"dE^2/dr is not finite at r={r} (tau={tau})")
    return value


def _bracket_from(counted, y0, tau, lower, upper, step, evaluations):
    """Walk downhill from y0 with doubling steps (the first `step`) until dE^2/dr changes sign.

    Returns (a, b, bound): the minimum lies in [a, b] (g(a) < 0 < g(b)); a == b is the answer
    itself (an exact zero of g, or a bracket end with bound -1 / +1); None when the
    `evaluations` allowed ran out first (then a == b is the furthest point reached downhill).
    """
    y = counted.on_grid(min(max(y0, lower), upper))
    g_y = _checked_grad(counted, y, tau)
    if g_y == 0.0:
        return y, y, 0
    direction = -1.0 if g_y > 0 else 1.0
    end = lower if direction < 0 else upper
    for _ in range(evaluations - 1):
        if y == end:
            return y, y, int(direction)  # downhill all the way to the bracket's end
        probe = counted.on_grid(min(max(y + direction * step, lower), upper))
        g_probe = _checked_grad(counted, probe, tau)
        if (g_probe > 0) != (g_y > 0) or g_probe == 0.0:
            return (y, probe, 0) if direction > 0 else (probe, y, 0)
        y, step = probe, 2.0 * step
    return (y, y, int(direction)) if y == end else (y, y, None)


def _level_bisection(counted, y0, tau, lower, upper, tol, max_steps):
    """One continuation level by bisection, warm-started at y0 (the previous level's answer).

    dE^2/dr is evaluated at y0 and at points walking downhill from it with doubling steps
    (first: `tol`) until its sign changes; the bracket is then halved at its midpoint until it
    is narrower than `tol`, and its midpoint returned. A warm start near the answer costs about
    three gradient evaluations per level, where bisecting the whole bracket at every level
    spends the budget before the last one. At most `max_steps` gradient evaluations; every point
    lies on the solve's float grid; a gradient that is not finite is an error. Returns
    ((r, bound), evaluations, converged) with bound -1 / +1 when the minimum is on the
    bracket's lower / upper edge.
    """
    before = counted.gradient
    a, b, bound = _bracket_from(counted, y0, tau, lower, upper, tol, max_steps)
    if bound is None or a == b:
        return (a, bound or 0), counted.gradient - before, bound is not None
    width = b - a
    # halvings until the bracket is narrower than tol
    needed = math.floor(math.log2(width / tol)) + 1 if width >= tol else 0
    steps = min(needed, max_steps - (counted.gradient - before))
    for _ in range(max(steps, 0)):
        mid = counted.on_grid(0.5 * (a + b))
        if not a < mid < b:  # the grid has no point strictly inside: as narrow as it gets
            break
        g = counted.grad(mid, tau)
        if not math.isfinite(g):
            raise FloatingPointError(f"dE^2/dr is not finite in [{a}, {b}] (tau={tau})")
        if g == 0.0:
            return (mid, 0), counted.gradient - before, True
        a, b = (a, mid) if g > 0 else (mid, b)
    return (counted.on_grid(0.5 * (a + b)), 0), counted.gradient - before, steps == needed


def solve(
    e2_soft: Callable[[Any, Any], Any],
    e_hard: Callable[[Any], Any],
    interval: tuple[float, float],
    *,
    steps: Sequence[float] | None = None,
    config: SolveConfig = SolveConfig(),
    sweep_points: Sequence[SweepPoint] | None = None,
    value_and_grad: Callable[[float, float], tuple[float, float]] | None = None,
    answer_name: str = "E_hard",
) -> SolveResult:
    """Find argmin_r E over `interval`: stepped sweep, then the continuous solve (module doc).

    Args:
        e2_soft: `e2_soft(r, tau) -> E^2 [m^2]`, pure, differentiable in r with jax.grad.
        e_hard: `e_hard(r) -> E [m]`, pure, piecewise constant, no gradient needed.
        interval: (lo, hi) in the objective's units.
        steps: the sweep's steps (default: `default_steps(lo, hi)`).
        config: solver settings.
        sweep_points: an already evaluated sweep (then `steps` is ignored).
        value_and_grad: optional host function `(r, tau) -> (E^2, dE^2/dr)` (floats), used for
            every soft evaluation instead of tracing `e2_soft` (an objective compiled and
            memoised elsewhere, e.g. `Evaluator`); `e2_soft` is then never traced.
        answer_name: what the notes call the objective `e_hard` evaluates (the caller knows:
            "E_ref" when it is the expectation over detection draws).

    Returns:
        A SolveResult. Raises InputError on a bad interval/steps/config and FloatingPointError
        if the objective's gradient is not finite.
    """
    lo, hi = check_interval(*interval)
    dtype = _outer_dtype(config.dtype)
    taus = tuple(float(t) for t in config.tau_schedule)
    t0 = time.perf_counter()
    if sweep_points is None:
        grid = check_steps(default_steps(lo, hi) if steps is None else steps, lo, hi)
        soft = ((lambda r, tau: value_and_grad(float(r), float(tau))[0]) if value_and_grad is not None
                else (lambda r, tau: e2_soft(jnp.asarray(r, dtype), jnp.asarray(tau, dtype))))
        sweep_points = sweep(
            lambda r: e_hard(jnp.asarray(r, dtype)),
            soft,
            grid,
            tau=taus[-1],
        )
    sweep_points = tuple(sweep_points)
    t1 = time.perf_counter()

    k = best_step(sweep_points)
    best = sweep_points[k]
    lower, upper = bracket_around(sweep_points, k, lo, hi)
    counted = _Counted(e2_soft, e_hard, dtype, value_and_grad)
    xtol = config.xtol_rel * (hi - lo)
    notes: list[str] = []

    levels: list[LevelResult] = []
    y, probe = best.r, 0.25 * (upper - lower)
    for i, tau in enumerate(taus):
        tol = min(xtol * tau / taus[-1], 0.125 * (upper - lower))
        used = counted.objective + counted.gradient
        later = len(taus) - 1 - i
        max_steps = config.max_evaluations - used - 2 - _RESERVE_PER_LEVEL * later - config._polish_reserve
        if max_steps < 1:
            notes.append(f"budget spent before tau={tau:g}: continuation stopped early")
            break
        if config.method == "secant":
            r, n, bound, done = _level_secant(
                counted, y, tau, lower, upper, probe, tol, max_steps, config.max_evaluations
            )
        else:
            (r, bound), n, done = _level_bisection(counted, y, tau, lower, upper, tol, max_steps)
        if not done:
            notes.append(f"tau={tau:g}: stopped after {n} gradient evaluations (budget share)")
        probe = max(2.0 * tol, abs(r - y)) if levels else max(2.0 * tol, 0.0625 * (upper - lower))
        y = r
        levels.append(
            LevelResult(tau=tau, r=r, gradient_evaluations=n, bound=bound, converged=done)
        )

    r_soft = levels[-1].r if levels else best.r
    last = levels[-1] if levels else None
    if last is not None and last.bound != 0 and r_soft not in (lo, hi):
        notes.append(
            f"the soft minimum at tau={last.tau:g} presses on the bracket edge r={r_soft:.6g}: "
            f"beyond it the sweep's {answer_name} is worse than at the best step r={best.r:.6g}"
        )
    r_star, e_hard_star = r_soft, counted.hard(r_soft)
    if e_hard_star > best.E_hard:
        candidates = [(e_hard_star, 0, r_soft)]
        for level in levels[:-1]:
            spent = counted.objective + counted.gradient
            if level.r != r_soft and spent < config.max_evaluations - 1:
                candidates.append((counted.hard(level.r), 0, level.r))
        candidates.append((best.E_hard, 1, best.r))
        e_hard_star, _, r_star = min(candidates)
        notes.append(
            f"the soft optimum r={r_soft:.6g} has {answer_name}={candidates[0][0]:.6g} m, worse than the "
            f"best step r={best.r:.6g} ({best.E_hard:.6g} m): the soft objective and {answer_name} disagree "
            f"there; answer r={r_star:.6g} is the best of {len(candidates)} candidates on {answer_name}"
        )
    spent = counted.objective + counted.gradient
    # One evaluation stays back for E_soft at a polished r*.
    probes = min(config.hard_polish, config.max_evaluations - spent - 1)
    if probes > 0:
        r_polished, e_polished = _hard_polish(counted, r_star, e_hard_star, lower, upper, probes, xtol)
        if r_polished != r_star:
            notes.append(
                f"hard polish: r={r_star:.6g} -> {r_polished:.6g} lowered {answer_name} from "
                f"{e_hard_star:.6g} to {e_polished:.6g} m (the soft objective cannot resolve "
                f"differences this fine)"
            )
            r_star, e_hard_star = r_polished, e_polished
    step_hit = next((p for p in sweep_points if p.r == r_star), None)
    e_soft_star = step_hit.E_soft if step_hit else _e_from_e2(counted.e2(r_star, taus[-1]))
    total = counted.objective + counted.gradient
    if total > config.max_evaluations:
        notes.append(f"{total} evaluations exceed the budget of {config.max_evaluations}")
    return SolveResult(
        r_star=float(r_star),
        E_soft_star=float(e_soft_star),
        E_hard_star=float(e_hard_star),
        sweep=sweep_points,
        evaluations={"objective": counted.objective, "gradient": counted.gradient},
        on_bound=r_star in (lo, hi),
        bracket=(float(lower), float(upper)),
        tau_schedule=taus,
        levels=tuple(levels),
        notes=tuple(notes),
        interval=(lo, hi),
        wall_s={"sweep": t1 - t0, "solve": time.perf_counter() - t1},
    )

