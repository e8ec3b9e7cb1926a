"""dr*/dtheta of an answer chosen on E_ref: the answer re-solved at theta moved both ways.

E_ref with common random numbers is a deterministic but piecewise-constant function of r (each
draw's detections switch where u = p(r)), its minimum can be narrower than any relaxed
objective's temperatures (radar HFOV 5-60 deg: a dip at 10 deg narrower than 2 deg), and its argmin
moves with theta in small jumps. So neither its own second derivatives (zero almost everywhere)
nor a relaxed objective's (another optimum) describe how the answer moves. Re-solving does: at theta - delta
and theta + delta (one-sided 0, delta, 2 delta where theta - delta leaves the domain: rain
below 0) the answer's own search runs again on the same draws (the sweep, then Brent in the
best step's bracket), and the slope of the line through the three answers is dr*/dtheta over
delta. Its standard error is the line's (one degree of freedom: the answers' second
difference, which the jumps make non-zero): a derivative of a jumping argmin holds at the
scale delta it was taken at, and the error says how far the jumps blur it.
"""

from __future__ import annotations

import math
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from diffsense.metrics import Objective, SpeedShiftedScenes, with_scenes
from diffsense.solve import SolveResult, brent_solve

THETA_STEP = {"rain_mm_h": 2.0, "traffic_speed_kmh": 5.0}  # delta [theta's unit]; fog: 10 % of it
_LOWER_BOUND = {"rain_mm_h": 0.0, "fog_visibility_m": 1.0}  # theta - delta must stay above


def moved_objective(E: Objective, how: str | SpeedShiftedScenes, shift) -> Objective:
    """E with every variant's weather `how` moved by `shift`, or over the scenes `how` at a
    traffic speed moved by `shift` [km/h]."""
    if isinstance(how, str):
        return eqx.tree_at(lambda o: getattr(o.weather, how), E, getattr(E.weather, how) + shift)
    return with_scenes(E, how(shift))


@eqx.filter_jit
def _e2_ref(E: Objective, how, param: str, r, shift):
    return moved_objective(E, how, shift).reference({param: r}).e2


def theta_step(E: Objective, theta: str) -> tuple[float, tuple[float, float, float]]:
    """(delta, the three theta offsets) at which the answer is taken for `theta` at E's ODD."""
    if theta == "fog_visibility_m":
        finite = [v for v in np.atleast_1d(np.asarray(E.weather.fog_visibility_m, float)) if math.isfinite(v)]
        delta = 0.1 * min(finite) if finite else 100.0
    else:
        delta = THETA_STEP[theta]
    if theta in _LOWER_BOUND:
        now = float(np.min(np.asarray(getattr(E.weather, theta), float)))
        if now - delta < _LOWER_BOUND[theta]:
            return delta, (0.0, delta, 2.0 * delta)
    return delta, (-delta, 0.0, delta)


def resolved_derivative(E: Objective, how: str | SpeedShiftedScenes, theta: str, param: str, solved: SolveResult,
                        xtol_rel: float, max_evaluations: int) -> dict[str, Any]:
    """{"value": dr*/dtheta, "se", "delta", "offsets", "r": the three answers, "evaluations"}:
    the answer `solved` re-solved on E_ref at theta moved by the offsets of `theta_step` (its
    own r* at offset 0) by the search that found it (`diffsense.solve.brent_solve`: its sweep's
    steps, then Brent in the best step's bracket); the slope of the least-squares line through
    the three (offset, answer) points and its standard error. `how` moves theta
    (`moved_objective`)."""
    steps = [p.r for p in solved.sweep]
    delta, offsets = theta_step(E, theta)
    answers, used = [], 0
    for shift in offsets:
        if shift == 0.0:
            answers.append(float(solved.r_star))
            continue

        def e_ref(r, shift=shift):
            e2 = _e2_ref(E, how, param, jnp.asarray(r, E.dtype), jnp.asarray(shift, E.dtype))
            return math.sqrt(max(float(e2), 0.0))

        again = brent_solve(e_ref, solved.interval, steps=steps, max_evaluations=max_evaluations, xtol_rel=xtol_rel)
        answers.append(again.r_star)
        used += len(steps) + again.evaluations["objective"]
    slope = float(np.polyfit(np.asarray(offsets), answers, 1)[0])
    second = answers[2] - 2.0 * answers[1] + answers[0]  # the offsets are evenly spaced
    return {"value": slope, "se": abs(second) / (math.sqrt(12.0) * delta), "delta": delta,
            "offsets": tuple(float(v) for v in offsets), "r": tuple(answers), "evaluations": used}
