"""The box solve: argmin of J = E + cost_weight * cost over many parameters with bounds.

Strategy:
1. a coarse space-filling sample of the box (a Halton sequence, randomly shifted by `seed`) is
   evaluated on the HARD objective; its best points are the starts. Where the functions offer a
   screen (`BoxFunctions.screen`: under a probabilistic detection law, E_ref on its first
   `screen_draws` draws, many points per compiled program), a larger sample (`screen_points`) is
   screened instead and only its best `starts` are evaluated on the hard objective: a point on
   a plateau (a sensor that sees almost nothing, J tens of metres above the optimum's) is told
   from a good one on a few draws, so the starts are not left to the luck of 2 d + 2 points;
2. from each start, optimistix BFGS minimises the SOFT J at each temperature of the
   continuation schedule, largest first, each level warm-started from the one before;
3. each start's answer at every temperature, and its iterate every `check_every` BFGS steps,
   is checked on the HARD objective, and the answer is the best hard J of all these and the
   sample points (never worse than the sample's best): a descent's progress becomes an answer
   as it is made, not only where a level ends;
4. at the answer: E_hard, E_soft, cost, the soft gradient per parameter at the last
   temperature, and which parameters lie on a bound.

The box is searched through MINUIT's sine transform: each parameter is
x = lo + (hi - lo) (1 + sin t) / 2 with t unconstrained, so every point a solver asks for lies
in [lo, hi] (clipped against rounding), and a minimum on a bound is an ordinary stationary
point in t (J changes quadratically in t there), which BFGS reaches instead of running off to
infinity. A parameter within `bound_tol` of a bound (relative to its box) is put on it and
flagged. BFGS starts from the identity inverse Hessian, so J is scaled per run (`_first_scale`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from diffsense.runtime import InputError
from diffsense.solve._box_fns import BoxFunctions, Event
from diffsense.solve._box_space import _Box, halton


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


class _Runner:
    """BFGS on the soft J in t, one optimistix step per Python iteration (so the soft budget is
    checked between steps), compiled once per solve; J reaches it through a host callback."""

    def __init__(self, fns: BoxFunctions, box: _Box, weight: float, config: BoxConfig):
        d = len(fns.names)
        vec, scalar = jax.ShapeDtypeStruct((d,), jnp.float64), jax.ShapeDtypeStruct((), jnp.float64)

        def call(t, tau, scale):
            return jax.pure_callback(self.j_t, (scalar, vec), t, tau, scale)

        @jax.custom_jvp
        def j(t, tau, scale):
            return call(t, tau, scale)[0]

        @j.defjvp
        def _jvp(primals, tangents):
            v, g = call(*primals)
            return v, jnp.dot(g, tangents[0])

        def fn(t, args):
            return j(t, *args), None

        tags = frozenset()
        # The solver is an argument (its tolerances arrays), so one program serves every level.
        self._init = eqx.filter_jit(lambda solver, t, args: solver.init(fn, t, args, {}, scalar, None, tags))
        self._step = eqx.filter_jit(lambda solver, t, args, state: solver.step(fn, t, args, {}, state, tags)[:2])
        self.fns, self.box, self.weight, self.config = fns, box, weight, config

    def j_t(self, t, tau, scale) -> tuple[np.float64, np.ndarray]:
        """scale * J at x(t) and its gradient in t (the chain rule through the sine transform)."""
        t = np.asarray(t, np.float64)
        j, g, _ = self.fns.j_soft(self.box.x(t), float(tau), self.weight)
        dxdt = self.box.width * 0.5 * np.cos(t)
        return np.float64(j * scale), np.asarray(g * dxdt * scale, np.float64)

    def tolerances(self, tau: float) -> tuple[float, float, float]:
        """(rtol, atol, ftol) at temperature tau: the config's, scaled by tau / tau_last, as the
        continuation only needs the last level exact."""
        loose = tau / float(self.config.tau_schedule[-1])
        return self.config.rtol * loose, self.config.atol * loose, self.config.ftol * loose

    def run(self, t0: np.ndarray, tau: float, budget: int,
            check: Callable[[np.ndarray], None] | None = None) -> tuple[np.ndarray, int]:
        """BFGS from t0 at temperature tau until the soft count reaches `budget`: (t at the end,
        steps taken). J is scaled by `_first_scale`. `check(t)` is called with the accepted
        iterate every `check_every` steps where it has moved since the last call."""
        j, g_t = self.j_t(t0, tau, 1.0)
        scale = _first_scale(float(j), float(np.max(np.abs(g_t))), self.config.first_step_rad)
        rtol, atol, ftol = self.tolerances(tau)
        solver = optx.BFGS(jnp.asarray(rtol), jnp.asarray(atol))
        args = (jnp.asarray(tau, jnp.float64), jnp.asarray(scale, jnp.float64))
        t = jnp.asarray(t0, jnp.float64)
        state = self._init(solver, t, args)
        steps, accepted, checked = 0, [], np.asarray(t0, np.float64)
        every = self.config.check_every
        while steps < self.config.max_steps and self.fns.counts["soft"] < budget:
            t, state = self._step(solver, t, args, state)
            steps += 1
            if check is not None and every and steps % every == 0 and not np.array_equal(np.asarray(t), checked):
                checked = np.asarray(t, np.float64)
                check(checked)
            # optimistix tests convergence on accepted steps only; near a minimum J's decrease
            # falls below rounding, Armijo rejects, and the steps shrink around the answer for
            # ever. So stop too when the next trial point moves t by less than the tolerance,
            # or when J has stopped falling (its last digits are below the soft/hard mismatch).
            move = float(jnp.max(jnp.abs(state.y_eval - t)))
            f = float(state.f_info.f)
            if not accepted or f != accepted[-1]:
                accepted.append(f)
            if (bool(state.terminate) or _stalled(accepted, ftol)
                    or _small_move(move, float(jnp.max(jnp.abs(t))), rtol, atol)):
                break
        return np.asarray(t, np.float64), steps


def _first_scale(j: float, g_max: float, first_step_rad: float) -> float:
    """The factor J is multiplied by in a BFGS run: 1 / |J(t0)| (a relative objective: steps do not
    depend on its units), smaller if the first step (the gradient in t, as BFGS starts from the
    identity inverse Hessian) would then move any t by more than `first_step_rad` [rad]; g_max is
    the largest |dJ/dt| at t0."""
    scale = 1.0 / max(abs(j), 1e-12)
    return first_step_rad / g_max if g_max * scale > first_step_rad else scale


def _stalled(accepted: Sequence[float], ftol: float) -> bool:
    """J has fallen by no more than ftol * |J| over its last 3 accepted steps (4 values)."""
    return len(accepted) >= 4 and accepted[-4] - accepted[-1] <= ftol * abs(accepted[-1])


def _small_move(move: float, t_max: float, rtol: float, atol: float) -> bool:
    """The next trial point moves t by at most atol + rtol * max|t| [rad]."""
    return move <= atol + rtol * t_max


def _check_bounds(names: Sequence[str], bounds: Any) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(bounds, dict):
        bounds = [bounds[n] for n in names]
    pairs = [tuple(float(v) for v in b) for b in bounds]
    if len(pairs) != len(names) or any(len(p) != 2 for p in pairs):
        raise InputError(f"need (lo, hi) for each of {len(names)} parameters, got {len(pairs)}")
    for n, (lo, hi) in zip(names, pairs):
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise InputError(f"bounds of {n} must be finite with lo < hi, got {lo:g} {hi:g}")
    return np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])


def _sample(fns: BoxFunctions, box: _Box, given: list[np.ndarray], config: BoxConfig) -> list[np.ndarray]:
    """The points evaluated on the hard objective before any descent: `given` and the Halton
    sample, or, where the functions can screen, the best `starts` of `given` and a larger
    Halton sample ranked on the screen's J (module doc, step 1)."""
    d = len(box.lo)
    if not (fns.can_screen and config.screen_points >= 0):
        return given + list(box.lo + box.width * halton(config.samples or 2 * d + 2, d, config.seed))
    points = given + list(box.lo + box.width * halton(config.screen_points or 8 * d + 8, d, config.seed))
    cost = np.array([fns.cost(p)[0] for p in points])
    order = np.argsort(fns.screen(np.array(points)) + config.cost_weight * cost, kind="stable")
    return [points[i] for i in order[: max(config.starts, 1)]]


def box_solve(fns: BoxFunctions, bounds: Any, config: BoxConfig = BoxConfig(),
              extra_starts: Sequence[Sequence[float]] = ()) -> BoxResult:
    """argmin of E + cost_weight * cost over the box `bounds` ({name: (lo, hi)} or a list in the
    order of `fns.names`); `extra_starts` are points added to the coarse sample (e.g. defaults)."""
    if not jax.config.jax_enable_x64:  # the solver's t and x are float64
        jax.config.update("jax_enable_x64", True)
    names, (lo, hi) = fns.names, _check_bounds(fns.names, bounds)
    d, lam, first, counts0 = len(names), config.cost_weight, len(fns.history), dict(fns.counts)
    budget = counts0["soft"] + config.max_soft
    box = _Box(lo, hi, config.bound_tol)
    points = _sample(fns, box, [box.x(box.t(p)) for p in extra_starts], config)  # outside the box: on its bound
    sample = sorted(((fns.j_hard(p, lam)[0], i) for i, p in enumerate(points)))
    runner = _Runner(fns, box, lam, config) if config.starts else None
    starts: list[StartResult] = []
    candidates = [(sample[0][0], "sample", points[sample[0][1]])]
    for k, (_, i) in enumerate(sample[: config.starts]):
        t, steps = box.t(points[i]), []
        for tau in config.tau_schedule:
            def check(t_now, label=f"start {k} tau {tau:g} step"):
                x_now, _ = box.snap(box.x(t_now))
                candidates.append((fns.j_hard(x_now, lam)[0], label, x_now))

            t, n = runner.run(t, float(tau), budget, check) if fns.counts["soft"] < budget else (t, 0)
            steps.append(n)
            x, _ = box.snap(box.x(t))
            j_hard = fns.j_hard(x, lam)[0]  # every level's answer: the hard check is one evaluation
            candidates.append((j_hard, f"start {k} tau {tau:g}", x))
        j_soft = fns.j_soft(x, float(config.tau_schedule[-1]), lam)[0]
        starts.append(StartResult(_named(names, points[i]), _named(names, x), j_soft, j_hard, tuple(steps)))
    j_star, source, x_star = min(candidates, key=lambda c: c[0])
    x_star, flags = box.snap(x_star)
    _, grad, e_soft = fns.j_soft(x_star, float(config.tau_schedule[-1]), lam)
    _, e_hard, cost = fns.j_hard(x_star, lam)
    _, g2 = fns.e2_soft(x_star, float(config.tau_schedule[-1]))
    grad_e = g2 / (2.0 * e_soft) if e_soft > 0 else np.zeros(d)
    return BoxResult(
        names=names, bounds={n: (float(a), float(b)) for n, a, b in zip(names, lo, hi)},
        x_star=_named(names, x_star), J_star=float(j_star), E_hard=e_hard, E_soft=e_soft, cost=cost,
        gradient=_named(names, grad), gradient_E=_named(names, grad_e), on_bound=dict(zip(names, flags)),
        source=source, starts=tuple(starts), counts={k: v - counts0.get(k, 0) for k, v in fns.counts.items()},
        history=tuple(fns.history[first:]),
        tau_schedule=tuple(float(t) for t in config.tau_schedule), cost_weight=float(lam))


def _named(names: Sequence[str], x) -> dict[str, float]:
    return {n: float(v) for n, v in zip(names, np.asarray(x, np.float64))}
