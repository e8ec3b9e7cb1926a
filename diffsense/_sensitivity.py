"""`sensitivity(problem, result, theta)`: how the best sensor setting moves with the ODD.

For an ODD parameter theta (the weather: "rain_mm_h", "fog_visibility_m") the optimum r*(theta) of
the soft objective at the final temperature satisfies dE^2/dr = 0, so by the implicit function
theorem dr*/dtheta = -(d2E^2/dr dtheta) / (d2E^2/dr2) at r* (`diffsense.solve.argmin_derivative`),
on the real objective: scenes, sensor and predictor. theta moves every scene variant's value by
the same amount (a scenario with its own weather keeps its offset). Zero on a bound: the
constraint stays active for small changes of theta. No re-solve is needed.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp

from diffsense._problem import Problem
from diffsense._result import Result
from diffsense.errors import InputError
from diffsense.metrics import Objective
from diffsense.solve import argmin_derivative

ODD_PARAMETERS = ("rain_mm_h", "fog_visibility_m")


@eqx.filter_jit
def _derivative(E: Objective, name: str, r_star, tau, on_bound):
    base = getattr(E.weather, name)
    param = E.names[0]

    def e2(r, shift):
        shifted = eqx.tree_at(lambda o: getattr(o.weather, name), E, base + shift)
        return shifted.e2({param: r}, tau)

    return argmin_derivative(e2, r_star, jnp.zeros((), E.dtype), on_bound=on_bound)


def sensitivity(problem: Problem, result: Result, theta: Sequence[str], *, E: Objective | None = None
                ) -> dict[str, dict[str, Any]]:
    """{theta: {param: dr*/dtheta}} [param units per theta unit]; 0 on a bound.

    The derivative is that of the soft optimum at the final temperature (the last continuation
    level's r, where dE^2/dr = 0), which the reported r* stays next to: the hard polish moves
    r* by less than the soft objective resolves. On a bound of the interval, or where the last
    level ended on its bracket's edge, the optimum is held by a constraint and the value is 0.
    `E` reuses an already built `diffsense.objective(problem)`. A value is None where the soft
    objective has no strict minimum there (the theorem does not apply).
    """
    from diffsense._optimise import objective

    unknown = [t for t in theta if t not in ODD_PARAMETERS]
    if unknown:
        raise InputError(f"no sensitivity to {unknown[0]!r}: the differentiable ODD parameters are "
                         f"{', '.join(ODD_PARAMETERS)}")
    if len(result.r_star) != 1:
        raise InputError("sensitivity is implemented for one-parameter problems")
    E = objective(problem) if E is None else E
    (param, r_star), = result.r_star.items()
    tau = result.solve.tau_schedule[-1] if result.solve.tau_schedule else 1.0
    levels = result.solve.levels
    held = result.on_bound or (bool(levels) and levels[-1].bound != 0)
    if levels:
        r_star = levels[-1].r
    out: dict[str, dict[str, Any]] = {}
    for name in theta:
        d = float(_derivative(E, name, jnp.asarray(r_star, E.dtype), jnp.asarray(tau, E.dtype),
                              jnp.asarray(held)))
        out[name] = {param: d if jnp.isfinite(d) else None}
    return out
