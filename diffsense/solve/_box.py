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

import math
from collections.abc import Callable, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from diffsense.runtime import InputError
from diffsense.solve._box_config import BoxConfig, BoxResult, StartResult
from diffsense.solve._box_fns import BoxFunctions
from diffsense.solve._box_space import _Box, halton


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
