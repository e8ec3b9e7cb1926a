"""`sensitivity(problem, result, theta)`: how the best sensor setting moves with the ODD.

The derivative is that of the optimum the answer was chosen on, on the real objective: scenes,
sensor and predictor. Zero on a bound: the constraint stays active for small changes of theta.

- An answer chosen on E_ref (a probabilistic detection law): the slope of the answers re-solved
  on E_ref at theta moved both ways (`_resolved`), E_ref's own optimum.
- An answer from the soft continuation (the threshold law): the optimum r*(theta) of the soft
  objective at the final temperature satisfies dE^2/dr = 0, so by the implicit function theorem
  dr*/dtheta = -(d2E^2/dr dtheta) / (d2E^2/dr2) there (`diffsense.solve.argmin_derivative`),
  with no re-solve.

- "rain_mm_h", "fog_visibility_m": the weather. theta moves every scene variant's value by the
  same amount (a scenario with its own weather keeps its offset).
- "traffic_speed_kmh": every vehicle's start speed, i.e. each scenario's ego speed (nominal and
  range; the others' are relative to it) and with it the desired speeds, which follow the start
  speeds. The scenes are re-simulated inside the derivative (the IDM simulation is JAX), and the
  ground-truth predictions with them, so E is differentiable in the speed. A uniform time or
  space scaling would not do: IDM's time headway, minimum gap and accelerations do not scale
  with speed, so a faster scene is not a rescaled slower one. The vehicles kept per scene are
  those kept at the problem's speed (their margins cover a small change); the derivative is that
  of the smooth part between the simulation's discrete events (leader switches, a follower
  becoming free). Recorded scenes have no speed knob and are refused.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from diffsense.metrics import Objective, SpeedShiftedScenes
from diffsense.runtime import InputError
from diffsense.solve import argmin_derivative
from diffsense.study._objective import objective, traffic_scenes
from diffsense.study._problem import Problem
from diffsense.study._resolved import moved_objective, resolved_derivative
from diffsense.study._result import Result

WEATHER_PARAMETERS = ("rain_mm_h", "fog_visibility_m")
ODD_PARAMETERS = (*WEATHER_PARAMETERS, "traffic_speed_kmh")


def check_theta(problem: Problem, theta: Sequence[str]) -> None:
    """InputError (one line) for an unknown theta, or one the problem's scenes cannot vary."""
    unknown = [t for t in theta if t not in ODD_PARAMETERS]
    if unknown:
        raise InputError(f"no sensitivity to {unknown[0]!r}: the differentiable ODD parameters are "
                         f"{', '.join(ODD_PARAMETERS)}")
    if "traffic_speed_kmh" in theta and problem.traffic.scenes is not None:
        raise InputError(f"no sensitivity to traffic_speed_kmh for recorded scenes ({problem.traffic.scenes}): "
                         "they move at the speeds they were recorded at")


@eqx.filter_jit
def _derivative(E: Objective, how, param: str, r_star, tau, on_bound):
    def e2(r, shift):
        return moved_objective(E, how, shift).e2({param: r}, tau)

    return argmin_derivative(e2, r_star, jnp.zeros((), E.dtype), on_bound=on_bound)


def odd_shift(problem: Problem, E: Objective, theta: str) -> Callable[[jax.Array], Objective]:
    """`shift -> E` with the ODD parameter `theta` moved by `shift` (its unit) from the problem's:
    the function whose derivatives `sensitivity` takes (jit-able, differentiable in `shift`)."""
    check_theta(problem, [theta])
    how = _speed_scenes(problem, E) if theta == "traffic_speed_kmh" else theta
    return lambda shift: moved_objective(E, how, shift)


def _speed_scenes(problem: Problem, E: Objective) -> SpeedShiftedScenes:
    return traffic_scenes(problem, E.spec, E.sensor, E.dtype)[0]


def sensitivity(problem: Problem, result: Result, theta: Sequence[str], *, E: Objective | None = None
                ) -> dict[str, dict[str, Any]]:
    """{theta: {param: dr*/dtheta}} [param units per theta unit]; 0 on a bound.

    The derivative is that of the optimum the answer was chosen on. An answer chosen on E_ref
    (a probabilistic detection law: `result.reference["answer_on"]`): the slope of the answers
    re-solved on E_ref at theta +- delta by the search that found it (`_resolved`: the sweep and
    Brent twice, about 36 E_ref programs per theta; delta 2 mm/h of rain, 5 km/h of traffic speed, 10 % of the fog
    visibility). Otherwise it is the soft optimum's at the final temperature (the last continuation
    level's r, where dE^2/dr = 0) by the implicit function theorem; the reported r* stays next
    to it, the hard polish moving r* by less than the soft objective resolves. On a bound of the
    interval, or where the last level ended on its bracket's edge, the optimum is held by a
    constraint and the value is 0. `E` reuses an already built `diffsense.objective(problem)`.
    A value is None where the objective has no strict minimum there (the local model's
    curvature is not positive).
    """
    return sensitivities(problem, result, theta, E=E)[0]


def sensitivities(problem: Problem, result: Result, theta: Sequence[str], *, E: Objective | None = None
                  ) -> tuple[dict[str, dict[str, Any]], tuple[str, ...]]:
    """`sensitivity`'s values, and a note per theta saying how each was taken and, for the
    re-solved answers, their slope's standard error."""
    check_theta(problem, theta)
    if len(result.r_star) != 1:
        raise InputError("sensitivity is implemented for one-parameter problems")
    E = objective(problem) if E is None else E
    (param, r_star), = result.r_star.items()
    on_e_ref = (result.reference or {}).get("answer_on") == "E_ref"
    levels = result.solve.levels
    held = result.on_bound or (not on_e_ref and bool(levels) and levels[-1].bound != 0)
    out: dict[str, dict[str, Any]] = {}
    notes = []
    for name in theta:
        if held:
            out[name] = {param: 0.0}
            notes.append(f"sensitivity to {name}: 0 (r* is held by a bound)")
            continue
        how = _speed_scenes(problem, E) if name == "traffic_speed_kmh" else name
        if on_e_ref:
            config = problem.solver.solve
            fit = resolved_derivative(E, how, name, param, result.solve, config.xtol_rel, config.max_evaluations)
            out[name] = {param: fit["value"]}
            notes.append(_resolved_note(name, fit))
        else:
            out[name] = {param: _implicit(E, how, param, result, r_star)}
            notes.append(f"sensitivity to {name}: the soft optimum's, by the implicit function theorem")
    return out, tuple(notes)


def _implicit(E: Objective, how, param: str, result: Result, r_star: float) -> float | None:
    tau = result.solve.tau_schedule[-1] if result.solve.tau_schedule else 1.0
    if result.solve.levels:
        r_star = result.solve.levels[-1].r
    args = (jnp.asarray(r_star, E.dtype), jnp.asarray(tau, E.dtype), jnp.asarray(False))
    d = float(_derivative(E, how, param, *args))
    return d if jnp.isfinite(d) else None


def _resolved_note(name: str, fit: dict[str, Any]) -> str:
    moved = ", ".join(f"{name} {b:+g}: r* {r:.5g}" for b, r in zip(fit["offsets"], fit["r"]))
    return (f"sensitivity to {name}: {fit['value']:.4g} +- {fit['se']:.2g} from answers re-solved on E_ref "
            f"({moved}; {fit['evaluations']} evaluations)")
