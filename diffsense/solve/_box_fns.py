"""What a box solve evaluates: soft E^2 with its gradient, hard E, and a cost, memoised and counted.

`BoxFunctions` wraps three (or four) host-side functions of a parameter vector x (values of
`names`, in that order):

    e2_soft(x, tau) -> (E^2 [m^2], dE^2/dx)    the smooth objective at temperature multiplier tau
    e_hard(x) -> E [m]                          the reference (0/1 detections)
    cost(x) -> (cost, dcost/dx)                 optional (`diffsense.metrics._cost.make_cost`)
    e_screen(X) -> E [m] per row of X [P, d]    optional: a cheaper, noisier e_hard of many
                                                points at once (E_ref on its first few draws)

and forms the solver's objective J = E + cost_weight * cost, soft or hard. Every distinct soft,
hard and screened evaluation is counted once (a repeated point costs nothing; counts["screen"]
is kept only once a screen has run) and recorded in order in `history`, so a benchmark can draw
the best value against the evaluations spent; `listener`, if set, is called with each new
`Event` (a progress display). Build it from a `diffsense.solve.Evaluator` (`from_evaluator`),
from jax functions (`from_jax`), or directly.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

SoftFn = Callable[[np.ndarray, float], tuple[float, np.ndarray]]
HardFn = Callable[[np.ndarray], float]
CostFn = Callable[[np.ndarray], tuple[float, np.ndarray]]
ScreenFn = Callable[[np.ndarray], np.ndarray]


@dataclasses.dataclass(frozen=True)
class Event:
    """One evaluation a solve made: kind "soft" (tau set, value E_soft [m]), "hard" (E_hard [m])
    or "screen" (the screen's cheaper E [m])."""

    kind: str
    x: tuple[float, ...]
    tau: float | None
    value: float


class BoxFunctions:
    """E_soft, E_hard and cost of a parameter vector, memoised, counted and recorded."""

    def __init__(self, names: Sequence[str], e2_soft: SoftFn, e_hard: HardFn, cost: CostFn | None = None,
                 e_screen: ScreenFn | None = None):
        self.names = tuple(names)
        self._e2_soft, self._e_hard, self._cost, self._e_screen = e2_soft, e_hard, cost, e_screen
        self.counts = {"soft": 0, "hard": 0}
        self.history: list[Event] = []
        self.listener: Callable[[Event], None] | None = None
        self._soft: dict[tuple, tuple[float, np.ndarray]] = {}
        self._hard: dict[tuple, float] = {}
        self._costs: dict[tuple, tuple[float, np.ndarray]] = {}
        self._screened: dict[tuple, float] = {}

    @classmethod
    def from_evaluator(cls, evaluator: Any, cost: Callable[[Mapping[str, Any]], Any] | None = None,
                       e_answer: HardFn | None = None, screen_draws: int | None = None,
                       batch: int = 8) -> BoxFunctions:
        """From a `diffsense.solve.Evaluator` (its objective's `names` order x); `cost` a
        jax-differentiable cost(r) over the same names (e.g. `make_cost(model, sensor)`);
        `e_answer` the objective answers are judged on in place of its E_hard (E_ref, under a
        probabilistic detection law); `screen_draws` K_s gives the screen: E_ref on its first K_s
        draws, `batch` points per program (`Evaluator.reference_batch`)."""
        names = evaluator.objective.names
        screen = None if screen_draws is None else (
            lambda xs: evaluator.reference_batch(xs, draws=screen_draws, batch=batch))
        return cls(names, evaluator.value_and_grad, e_answer or evaluator.e_hard,
                   None if cost is None else _jit_cost(names, cost), screen)

    @classmethod
    def from_jax(cls, names: Sequence[str], e2_soft: Callable, e_hard: Callable,
                 cost: Callable | None = None) -> BoxFunctions:
        """From jax functions of a float64 vector x: e2_soft(x, tau), e_hard(x), cost(x) (scalars)."""
        vg = jax.jit(jax.value_and_grad(e2_soft))
        hard = jax.jit(e_hard)
        cost_vg = None if cost is None else jax.jit(jax.value_and_grad(cost))

        def soft(x, tau):
            v, g = vg(jnp.asarray(x, jnp.float64), jnp.asarray(tau, jnp.float64))
            return float(v), np.asarray(g, np.float64)

        def cost_fn(x):
            v, g = cost_vg(jnp.asarray(x, jnp.float64))
            return float(v), np.asarray(g, np.float64)

        return cls(names, soft, lambda x: float(hard(jnp.asarray(x, jnp.float64))), None if cost is None else cost_fn)

    # -- the three functions, memoised ---------------------------------------------------------
    @staticmethod
    def _key(x) -> tuple[float, ...]:
        return tuple(float(v) for v in np.asarray(x, np.float64).ravel())

    def e2_soft(self, x, tau: float) -> tuple[float, np.ndarray]:
        """Soft E^2 [m^2] and its gradient."""
        key = (self._key(x), float(tau))
        if key not in self._soft:
            v, g = self._e2_soft(np.asarray(key[0]), key[1])
            self._soft[key] = (float(v), np.asarray(g, np.float64).reshape(len(self.names)))
            self.counts["soft"] += 1
            self._record(Event("soft", key[0], key[1], math.sqrt(max(float(v), 0.0))))
        return self._soft[key]

    def e_hard(self, x) -> float:
        """Hard E [m]."""
        key = self._key(x)
        if key not in self._hard:
            self._hard[key] = float(self._e_hard(np.asarray(key)))
            self.counts["hard"] += 1
            self._record(Event("hard", key, None, self._hard[key]))
        return self._hard[key]

    @property
    def can_screen(self) -> bool:
        return self._e_screen is not None

    def screen(self, xs) -> np.ndarray:
        """The screen's E [m] of each row of xs [P, d], memoised: the new points in one call
        (batched programs)."""
        keys = [self._key(x) for x in np.atleast_2d(np.asarray(xs, np.float64))]
        new = list(dict.fromkeys(k for k in keys if k not in self._screened))
        if new:
            values = np.asarray(self._e_screen(np.array(new)), np.float64).reshape(len(new))
            for key, v in zip(new, values):
                self._screened[key] = float(v)
                self.counts["screen"] = self.counts.get("screen", 0) + 1
                self._record(Event("screen", key, None, float(v)))
        return np.array([self._screened[k] for k in keys])

    def _record(self, event: Event) -> None:
        self.history.append(event)
        if self.listener is not None:
            self.listener(event)

    def cost(self, x) -> tuple[float, np.ndarray]:
        """cost [currency] and its gradient (0 without a cost function)."""
        if self._cost is None:
            return 0.0, np.zeros(len(self.names))
        key = self._key(x)
        if key not in self._costs:
            v, g = self._cost(np.asarray(key))
            self._costs[key] = (float(v), np.asarray(g, np.float64).reshape(len(self.names)))
        return self._costs[key]

    # -- the solver's objective J = E + weight * cost ------------------------------------------
    def j_soft(self, x, tau: float, weight: float) -> tuple[float, np.ndarray, float]:
        """(J, dJ/dx, E_soft) with J = E_soft + weight * cost; dE/dx = dE^2/dx / (2E), 0 at E = 0."""
        e2, g2 = self.e2_soft(x, tau)
        e = math.sqrt(max(e2, 0.0))
        grad_e = g2 / (2.0 * e) if e > 0 else np.zeros_like(g2)
        c, gc = self.cost(x)
        return e + weight * c, grad_e + weight * gc, e

    def j_hard(self, x, weight: float) -> tuple[float, float, float]:
        """(J, E_hard, cost) with J = E_hard + weight * cost."""
        e = self.e_hard(x)
        c = self.cost(x)[0]
        return e + weight * c, e, c


def _jit_cost(names: Sequence[str], cost: Callable) -> CostFn:
    vg = jax.jit(jax.value_and_grad(lambda v: cost({n: v[i] for i, n in enumerate(names)})))

    def fn(x):
        v, g = vg(jnp.asarray(x, jnp.float64))
        return float(v), np.asarray(g, np.float64)

    return fn
