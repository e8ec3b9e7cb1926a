"""dr*/dtheta: how the best parameter moves with a scenario or ODD parameter theta.

At an interior optimum g(r*, theta) = dE^2/dr = 0 with d2E^2/dr2 > 0, so by the implicit
function theorem

    dr*/dtheta = - (d2E^2 / dr dtheta) / (d2E^2 / dr2).

On a bound the optimum stays on the bound for small changes of theta (the constraint is
active), so dr*/dtheta = 0 there. Two routes, tested to agree: `argmin_derivative` (the formula,
second derivatives by forward-over-reverse AD) and `argmin` (an optimistix root find of g with
`optx.ImplicitAdjoint`, so jax.grad / jax.jvp of its result is dr*/dtheta).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, ArrayLike, Bool, PyTree, Scalar

from diffsense.solve._bracketed import BracketedSecant


def argmin_derivative(
    e2_soft: Callable[[Scalar, PyTree], Scalar],
    r_star: ArrayLike,
    theta: PyTree,
    *,
    on_bound: Bool[ArrayLike, ""] = False,
) -> PyTree:
    """dr*/dtheta by the implicit function theorem (zero on a bound).

    Args:
        e2_soft: `e2_soft(r, theta) -> E^2`, twice differentiable in (r, theta).
        r_star: the optimum r* (a scalar, the dtype of the outer problem).
        theta: the scenario/ODD parameter: a scalar, an array or a pytree of them.
        on_bound: r* is on an end of the interval (traced booleans are fine).

    Returns:
        dr*/dtheta, shaped like theta. Where d2E^2/dr2 <= 0 (no strict minimum: the implicit
        function theorem does not apply) the entries are NaN; on a bound they are 0.
    """
    r_star = jnp.asarray(r_star)

    def g(r, th):
        return jax.grad(e2_soft, argnums=0)(r, th)

    curvature = jax.grad(g, argnums=0)(r_star, theta)
    cross = jax.grad(g, argnums=1)(r_star, theta)
    strict = curvature > 0
    safe_curvature = jnp.where(strict, curvature, 1.0)
    interior = jnp.logical_not(jnp.asarray(on_bound))

    def leaf(c: Array) -> Array:
        value = jnp.where(strict, -c / safe_curvature, jnp.nan)
        return jnp.where(interior, value, jnp.zeros_like(value))

    return jax.tree_util.tree_map(leaf, cross)


def argmin(
    e2_soft: Callable[[Scalar, PyTree], Scalar],
    theta: PyTree,
    lower: ArrayLike,
    upper: ArrayLike,
    *,
    r0: ArrayLike | None = None,
    xtol: float = 1e-10,
    max_steps: int = 200,
) -> tuple[Scalar, Bool[Array, ""]]:
    """The minimum of e2_soft(., theta) on [lower, upper], differentiable in theta.

    A root find of dE^2/dr with `BracketedSecant` and `optx.ImplicitAdjoint`: jax.grad of the
    returned r* with respect to theta is dr*/dtheta at an interior minimum, and 0 when the
    minimum is on a bound (then r* is held by the constraint).

    Args:
        e2_soft: `e2_soft(r, theta) -> E^2`.
        theta: the scenario/ODD parameter (pytree).
        lower, upper: the bracket; r's dtype is theirs.
        r0: the start (default: the middle of the bracket).
        xtol: tolerance on r.
        max_steps: gradient evaluations at most.

    Returns:
        (r_star, on_bound).
    """
    lower = jnp.asarray(lower)
    upper = jnp.asarray(upper, lower.dtype)
    if r0 is None:
        y0 = 0.5 * (lower + upper)
    else:
        y0 = jnp.clip(jnp.asarray(r0, lower.dtype), lower, upper)

    def g(r, th):
        return jax.grad(e2_soft, argnums=0)(r, th)

    sol = optx.root_find(
        g,
        BracketedSecant(rtol=0.0, atol=xtol),
        y0,
        args=theta,
        options=dict(lower=lower, upper=upper),
        max_steps=max_steps,
        adjoint=optx.ImplicitAdjoint(),
        throw=False,
    )
    on_bound = sol.state.bound != 0
    r_star = jnp.where(on_bound, jax.lax.stop_gradient(sol.value), sol.value)
    return r_star, on_bound

