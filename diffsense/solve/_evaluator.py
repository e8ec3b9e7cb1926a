"""The solver's thin wrapper around a pure objective: compiled once, memoised, counted.

The objective (`diffsense.metrics.Objective`) is pure and stateless; a solve asks for the same
point more than once (a sweep step again for a figure, the answer's hard value), so the wrapper
keeps every evaluation by (r, tau), counts the programs actually run, and compiles one program
per kind of evaluation it is asked for: the soft value-and-gradient, the hard evaluation, the
reference (E_ref), the reference of many points at once (vmap over r, on the first few draws:
a screen) and the detections. The objective is an argument of each program, never a closure, so XLA does not fold
its data in as constants.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from diffsense.metrics import (
    PartSums,
    ReferenceEvaluation,
    SceneSums,
    breakdown,
    drawn_breakdown,
    drawn_part_sums,
    drawn_tracked_summary,
    hard_part_sums,
    is_deterministic,
    scene_sums,
    tracked_summary,
    value_and_grad,
)
from diffsense.runtime import call, to_host
from diffsense.solve._solve_config import host_array


def _deterministic(objective: Any) -> bool:
    sensor = getattr(objective, "sensor", None)
    return sensor is not None and is_deterministic(sensor)


def _value_and_grad(objective, x, tau):
    # forward mode for one parameter (one tangent through the CS-LSTM), reverse mode for more
    return value_and_grad(lambda v: objective.e2(objective.point(v), tau))(x)


def _hard(objective, x):
    return objective.hard(objective.point(x))


def _reference(objective, x):
    return objective.reference(objective.point(x))


def _reference_batch(objective, xs, draws):
    # one program for B points: vmap over r grows every product of the predictor by B
    return jax.vmap(lambda x: objective.reference(objective.point(x), draws).e)(xs)


def _detections(objective, x, tau, mode):
    return objective.detections(objective.point(x), mode, tau)


class Evaluator:
    """Evaluations of `objective` at points x (values of `objective.names`, in that order).

    `counts` holds how many soft and hard programs have run; asking again for an evaluated
    point costs nothing. One-parameter problems may pass x as a float.
    """

    def __init__(self, objective: Any, progress: Callable[[str, float, float], None] | None = None):
        self.objective = objective
        self.dtype = objective.dtype
        self.counts = {"soft": 0, "hard": 0}
        self._soft: dict[tuple, tuple[float, np.ndarray]] = {}
        self._hard: dict[tuple, Any] = {}
        self._reference: dict[tuple, Any] = {}
        self._drawn_breakdown: dict[tuple, dict[str, Any]] = {}
        self._drawn_sums: dict[tuple, SceneSums] = {}
        self._drawn_part_sums: dict[tuple, PartSums] = {}
        self._scenes: tuple[np.ndarray, np.ndarray] | None = None
        self.reference_count = 0  # reference programs run (each K hard passes for a random law)
        self._progress = progress

    def _array(self, values) -> np.ndarray:
        return host_array(values, self.dtype)

    def _key(self, x) -> tuple[float, ...]:
        return tuple(float(v) for v in np.atleast_1d(np.asarray(x, dtype=np.float64)))

    def value_and_grad(self, x, tau: float = 1.0) -> tuple[float, np.ndarray]:
        """Soft E^2 [m^2] and its gradient with respect to x, gate temperatures scaled by tau."""
        key = (self._key(x), float(tau))
        if key not in self._soft:
            self.counts["soft"] += 1
            v, g = call(_value_and_grad, self.objective, self._array(key[0]), self._array(key[1]))
            v, g = to_host((v, g))  # gathered from every process of a distributed run
            self._soft[key] = (float(v), np.asarray(g, np.float64))
            if self._progress:
                self._progress("soft", float(np.sqrt(max(float(v), 0.0))), key[1])
        return self._soft[key]

    def hard(self, x):
        """The hard evaluation (`HardEvaluation`, numpy leaves) at x."""
        key = self._key(x)
        if key not in self._hard:
            self.counts["hard"] += 1
            out = call(_hard, self.objective, self._array(key))
            self._hard[key] = to_host(out)
            if self._progress:
                self._progress("hard", float(np.sqrt(max(float(self._hard[key].e2), 0.0))), 0.0)
        return self._hard[key]

    def breakdown(self, x, of_reference: bool = True) -> dict[str, Any]:
        """E at x broken down by scenario, horizon step and coverage, with the "tracked"
        question's figures pooled (`"tracked"`) and per scenario; layout of result.json's.

        Under a probabilistic law and `of_reference`, the breakdown of E_ref over its detection
        draws (keys "E_ref"; read from the reference evaluation, no program of its own);
        otherwise of E_hard, each detection at its median (keys "E_hard")."""
        if of_reference and not _deterministic(self.objective):
            self.reference(x)
            if self._key(x) in self._drawn_breakdown:  # an objective of ours (a custom one keeps no draws)
                return self._drawn_breakdown[self._key(x)]
        E, hard = self.objective, self.hard(x)
        scenario, weight = self._scene_weights()
        out = breakdown(hard, scenario, weight, E.scenario_names, E.spec.horizon_s())
        return out | {"tracked": tracked_summary(hard, weight, float(E.miss_penalty_m2))}

    def _scene_weights(self) -> tuple[np.ndarray, np.ndarray]:
        """Each variant's scenario index and weight, on the host (fetched once)."""
        if self._scenes is None:
            E = self.objective
            self._scenes = to_host((E.data.scenario, E.data.weight))
        return self._scenes

    def _keep_reference(self, key: tuple, ref: ReferenceEvaluation) -> None:
        """Memoise a reference evaluation: its value, and its draws' breakdown in place of the
        draws' arrays (a few MB a point that a dense grid would otherwise keep by the hundred)."""
        if getattr(ref, "parts", None) is None:  # a custom objective's: its value alone
            self._reference[key] = ref
            return
        E = self.objective
        scenario, weight = self._scene_weights()
        self._drawn_breakdown[key] = (
            drawn_breakdown(ref.parts, scenario, weight, E.scenario_names, E.spec.horizon_s())
            | {"tracked": drawn_tracked_summary(ref.parts, weight, float(E.miss_penalty_m2))})
        self._drawn_sums[key] = scene_sums(ref.parts.sq_instant, ref.parts.coverage, weight, E.question,
                                           float(E.miss_penalty_m2))
        self._drawn_part_sums[key] = drawn_part_sums(ref.parts, scenario, weight, E.scenario_names)
        self._reference[key] = dataclasses.replace(ref, parts=None)

    def scene_sums(self, x, of_reference: bool = True) -> SceneSums | None:
        """The per-variant sums E at x is a ratio of (`diffsense.metrics.SceneSums`), from the
        evaluation made there (no program of its own beyond it): of E_ref over its detection
        draws under a probabilistic law and `of_reference`, otherwise of E_hard. None for a
        custom objective's reference, which keeps no draws."""
        E = self.objective
        if of_reference and not _deterministic(E):
            self.reference(x)
            return self._drawn_sums.get(self._key(x))
        hard = self.hard(x)
        return scene_sums(hard.sq_instant, hard.coverage, self._scene_weights()[1], E.question,
                          float(E.miss_penalty_m2))

    def part_sums(self, x, of_reference: bool = True) -> PartSums | None:
        """The breakdown's parts at x as per-variant sums (`diffsense.metrics.PartSums`), of the
        breakdown `breakdown(x, of_reference)` gives; None where `scene_sums` is None."""
        E = self.objective
        if of_reference and not _deterministic(E):
            self.reference(x)
            return self._drawn_part_sums.get(self._key(x))
        scenario, weight = self._scene_weights()
        return hard_part_sums(self.hard(x), scenario, weight, E.scenario_names)

    def reference(self, x):
        """The reference evaluation (`ReferenceEvaluation`, numpy leaves) at x: E_ref and its
        standard error."""
        key = self._key(x)
        if key not in self._reference and _deterministic(self.objective):
            # One draw, the hard objective itself: read from the hard evaluation (memoised, and
            # no second program to compile for the same numbers).
            e2 = np.asarray(self.hard(x).objective)
            e = np.sqrt(np.maximum(e2, 0.0))
            self._reference[key] = ReferenceEvaluation(e2=e2, e2_se=np.zeros_like(e2), e=e, e_se=np.zeros_like(e2),
                                                       draws=e2[None])
        if key not in self._reference:
            self.reference_count += 1
            self._keep_reference(key, to_host(call(_reference, self.objective, self._array(key))))
            if self._progress:
                self._progress("reference", float(self._reference[key].e), 0.0)
        return self._reference[key]

    def reference_batch(self, xs, draws: int | None = None, batch: int = 8) -> np.ndarray:
        """E_ref [m] of each row of `xs` [P, d] on its first `draws` detection draws (None: all
        K), `batch` points per compiled program (vmap over r; the last batch padded with its
        last point, so one program serves any P). With common random numbers the first draws
        are E_ref's own: a value on fewer draws is the same estimator, noisier. Not memoised."""
        xs = np.atleast_2d(np.asarray(xs, np.float64))
        k = self.objective.estimator.reference_draws if draws is None else int(draws)
        ids = np.arange(k, dtype=np.int32)
        out = []
        for start in range(0, len(xs), batch):
            chunk = xs[start:start + batch]
            padded = np.concatenate([chunk, np.repeat(chunk[-1:], batch - len(chunk), axis=0)])
            values = to_host(call(_reference_batch, self.objective, self._array(padded), ids))
            out.append(np.asarray(values, np.float64)[: len(chunk)])
        return np.concatenate(out) if out else np.zeros(0)

    def e_reference(self, x) -> float:
        """E_ref [m]: the hard objective's expectation over detection draws."""
        return float(self.reference(x).e)

    def reference_points(self) -> list[tuple[float, ...]]:
        """Every point evaluated on the reference objective so far."""
        return list(self._reference)

    def soft_points(self, tau: float) -> list[tuple[float, ...]]:
        """Every point evaluated on the soft value-and-gradient at temperature multiplier `tau`."""
        return [x for x, t in self._soft if t == float(tau)]

    def hard_points(self) -> list[tuple[float, ...]]:
        """Every point evaluated on the hard objective so far."""
        return list(self._hard)

    def e_hard(self, x) -> float:
        """E [m] with hard (0/1) detections."""
        return float(np.sqrt(max(float(self.hard(x).e2), 0.0)))

    def e2_soft(self, x, tau: float = 1.0) -> float:
        return self.value_and_grad(x, tau)[0]

    def detections(self, x, mode: str = "hard", tau: float = 1.0):
        return call(_detections, self.objective, self._array(self._key(x)), self._array(tau), mode)

    def host_value_and_grad(self, r: float, tau: float) -> tuple[float, float]:
        """(E^2, dE^2/dr) of a one-parameter objective as floats: `solve`'s `value_and_grad`."""
        v, g = self.value_and_grad(r, tau)
        return v, float(g[0])

    def solver_fns(self, dtype=jnp.float64) -> tuple[Callable[[Any, Any], Any], Callable[[Any], float]]:
        """(e2_soft, e_hard) of a one-parameter objective in the form `diffsense.solve.solve` takes.

        `e2_soft(r, tau)` is traceable and differentiable in r; inside a compiled solver loop it
        reaches this wrapper's compiled program through a host callback, so the loop does not
        compile the objective a second time and every evaluation is memoised and counted here.
        Give `solve` `host_value_and_grad` too, and it never traces this one: every evaluation
        goes straight to the compiled program.
        """
        spec = jax.ShapeDtypeStruct((), dtype)

        def host(r, tau):
            v, g = self.value_and_grad(float(r), float(tau))
            return np.asarray(v, dtype), np.asarray(g[0], dtype)

        def callback(r, tau):
            return jax.pure_callback(host, (spec, spec), r, tau)

        @jax.custom_jvp
        def e2_soft(r, tau):
            return callback(r, tau)[0]

        @e2_soft.defjvp
        def _jvp(primals, tangents):
            v, g = callback(*primals)
            return v, g * tangents[0]

        return e2_soft, lambda r: self.e_hard(float(r))
