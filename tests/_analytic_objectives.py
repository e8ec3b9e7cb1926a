"""Analytic 1-D stand-ins for E_RMSE(r): the solver's tests and benchmark use them.

Each is a pair (e2_soft(r, tau) -> E^2 [m^2], e_hard(r) -> E [m]) over r in radians (HFOV),
shaped like the real objective: a bowl, or a bowl seen through a staircase of logistic gates
(every gate a vehicle crossing the FOV edge) that turns into hard steps as tau -> 0.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

LO, HI = float(np.deg2rad(30.0)), float(np.deg2rad(180.0))
# Staircase: a gate every STEP_W rad, logistic width STEP_TEMP * tau rad.
STEP_W = 0.05
STEP_TEMP = 0.01


def bowl(center: float):
    """E^2 = 1 + (r - center)^2, the same hard and soft (no temperature)."""

    def e2_soft(r, tau):
        del tau
        return 1.0 + (r - center) ** 2

    def e_hard(r):
        return jnp.sqrt(1.0 + (jnp.asarray(r) - center) ** 2)

    return e2_soft, e_hard


def staircase(center: float):
    """E^2 = 1 + (q(r) - center)^2 with q a staircase of gates: plateaus and steps."""
    edges = STEP_W * jnp.arange(80)

    def e2_soft(r, tau):
        q = STEP_W * jnp.sum(jax.nn.sigmoid((r - edges) / (STEP_TEMP * tau)))
        return 1.0 + (q - center) ** 2

    def e_hard(r):
        q = STEP_W * jnp.sum(jnp.asarray(r) >= edges)
        return jnp.sqrt(1.0 + (q - center) ** 2)

    return e2_soft, e_hard


def dip_at(r_dip: float, center: float, penalty: float = 0.5):
    """A bowl whose hard objective is `penalty` worse everywhere but within 0.01 of r_dip."""
    e2_soft, e_hard_bowl = bowl(center)

    def e_hard(r):
        return e_hard_bowl(r) + penalty * (jnp.abs(jnp.asarray(r) - r_dip) > 0.01)

    return e2_soft, e_hard


def ripple(center: float, amplitude: float = 0.02, wavenumber: float = 40.0, width: float = 0.02):
    """A bowl with ripples (local minima every 9 deg) that a temperature smooths away.

    The soft objective is the hard one convolved with a Gaussian of std `width * tau` rad, which
    damps the ripple by exp(-(width tau k)^2 / 2): 0.73 at tau = 1, 0.006 at tau = 4.
    """

    def e2_soft(r, tau):
        damping = jnp.exp(-0.5 * (tau * width * wavenumber) ** 2)
        return 1.0 + (r - center) ** 2 + amplitude * damping * jnp.sin(wavenumber * r)

    def e_hard(r):
        r = jnp.asarray(r)
        return jnp.sqrt(1.0 + (r - center) ** 2 + amplitude * jnp.sin(wavenumber * r))

    return e2_soft, e_hard
