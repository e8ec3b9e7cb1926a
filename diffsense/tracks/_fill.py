"""Fill policies for missed detections, one formula for soft and hard mode.

Each policy maps measured points z_k and detection probabilities p_k (k along a history window)
to the expected point the predictor sees, x_k = p_k z_k + (1 - p_k) fill_k:

- `zero`:   fill = 0 (the paper's pipeline: a missing point becomes the origin, i.e. the target's
            own position at the prediction instant).
- `hold`:   fill = the last detected value (0 before the first detection).
- `interp`: fill = linear interpolation between the nearest detections either side (the paper's
            imputation test); the nearest detection where only one side has one; 0 where none.

With p in {0, 1} the formulas reduce exactly to the hard policies (tested); with soft p they are
smooth expectations under p. Everything is a linear recurrence over the window, so no log, no
division by anything that can meet 0 without a safe `where`.
"""

from __future__ import annotations

from typing import Literal

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

FillPolicy = Literal["zero", "hold", "interp"]
FILL_POLICIES: tuple[str, ...] = ("zero", "hold", "interp")


def _forward_hold(z: Float[Array, "W ... 2"], p: Float[Array, "W ..."]):
    """Soft last-detected value F, probability of any detection so far h, and steps since it a."""

    def step(carry, zp):
        f, h, a = carry
        zk, pk = zp
        f = pk[..., None] * zk + (1.0 - pk[..., None]) * f
        h = pk + (1.0 - pk) * h
        a = (1.0 - pk) * (a + 1.0)
        return (f, h, a), (f, h, a)

    init = (jnp.zeros_like(z[0]), jnp.zeros_like(p[0]), jnp.zeros_like(p[0]))
    _, out = jax.lax.scan(step, init, (z, p))
    return out


def fill_window(z: Float[Array, "... W 2"], p: Float[Array, "... W"], policy: FillPolicy) -> Float[Array, "... W 2"]:
    """Apply a fill policy along the window axis (-2 of `z`, -1 of `p`)."""
    if policy == "zero":
        return p[..., None] * z
    # Time first for the scans.
    zt = jnp.moveaxis(z, -2, 0)
    pt = jnp.moveaxis(p, -1, 0)
    fwd, h_fwd, a = _forward_hold(zt, pt)
    if policy == "hold":
        return jnp.moveaxis(fwd, 0, -2)
    if policy != "interp":
        raise ValueError(f"unknown fill policy {policy!r} (known: {', '.join(FILL_POLICIES)})")
    bwd, h_bwd, b = (x[::-1] for x in _forward_hold(zt[::-1], pt[::-1]))
    # Interpolation weights: the left value counts with the distance to the right detection and
    # vice versa; a side without any detection (h = 0) drops out.
    w_left = b * h_fwd
    w_right = a * h_bwd
    den = w_left + w_right
    safe_den = jnp.where(den > 0.0, den, 1.0)
    fill = (b[..., None] * fwd + a[..., None] * bwd) / safe_den[..., None]
    fill = jnp.where((den > 0.0)[..., None], fill, 0.0)
    x = pt[..., None] * zt + (1.0 - pt[..., None]) * fill
    return jnp.moveaxis(x, 0, -2)
