"""Hand-built scenes for the sensor tests (no dependence on the scene engine); no tests here."""

from __future__ import annotations

import numpy as np

import jax
import jax.numpy as jnp

from diffsense import sensors as sensor
from diffsense.scene import CAR, Scene


def make_scene(x_m, y_m, *, heading_rad=None, length_m=4.5, width_m=1.8, kind=CAR,
               present=True, dtype=np.float64) -> Scene:
    """A straight-road scene (road angle 0) from world positions [T, V]; vehicle 0 is the ego."""
    x = np.atleast_2d(np.asarray(x_m, dtype))
    y = np.broadcast_to(np.asarray(y_m, dtype), x.shape)
    t, v = x.shape
    heading = np.zeros((t, v), dtype) if heading_rad is None else np.broadcast_to(
        np.asarray(heading_rad, dtype), x.shape)
    zeros = np.zeros((t, v), dtype)
    return Scene(
        s_m=jnp.asarray(x), d_m=jnp.asarray(y), x_m=jnp.asarray(x), y_m=jnp.asarray(y),
        heading_rad=jnp.asarray(heading), road_angle_rad=jnp.asarray(zeros),
        speed_mps=jnp.asarray(zeros), lane=jnp.zeros((t, v), jnp.int32),
        length_m=jnp.asarray(np.broadcast_to(np.asarray(length_m, dtype), (v,))),
        width_m=jnp.asarray(np.broadcast_to(np.asarray(width_m, dtype), (v,))),
        kind=jnp.asarray(np.broadcast_to(np.asarray(kind), (v,)), jnp.int32),
        role=jnp.asarray(np.minimum(np.arange(v), 5), jnp.int32),
        present=jnp.asarray(np.broadcast_to(np.asarray(present), (v,))),
    )


def traffic_scene(num_frames=20, dtype=np.float64) -> Scene:
    """Ego, target and five neighbours on a three-lane straight road, plus one padding slot."""
    x0 = np.array([0.0, 30.0, 55.0, 20.0, -15.0, 60.0, 90.0, 0.0])
    y0 = np.array([0.0, 3.7, 3.7, -3.7, 3.7, 0.0, -3.7, 0.0])
    speed = np.array([25.0, 24.0, 26.0, 27.0, 25.0, 23.0, 24.0, 0.0])
    t = np.arange(num_frames)[:, None] * 0.1
    x = x0 + speed * t
    y = np.broadcast_to(y0, x.shape).copy()
    y[:, 1] = 3.7 - 3.7 * np.clip(t[:, 0] / max(t[-1, 0], 1e-9), 0, 1)  # target cuts in
    kinds = np.array([0, 0, 2, 1, 0, 0, 0, 0])
    present = np.array([True] * 7 + [False])
    return make_scene(x, y, kind=kinds, present=present, dtype=dtype)


# Compiled once per (shape, config, mode) and shared by the sensor tests: eager JAX compiles
# every primitive separately, which is far slower on the test machine.
jit_p_detect = jax.jit(sensor.p_detect, static_argnames=("config", "mode"))
jit_detect = jax.jit(sensor.detect, static_argnames=("config", "mode"))
