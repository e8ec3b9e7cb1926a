"""Small hand-built scenes for tests that must not depend on the scenario engine."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from diffsense.scene import Scene

LANE_M = 3.66


def straight_scene(
    s0_m, lane, speed_mps, num_frames: int = 101, dt_s: float = 0.1, lane_change=None, dtype=np.float64
) -> Scene:
    """Vehicles at constant speed on a straight road along +x (road angle 0).

    s0_m, lane, speed_mps: per-vehicle initial arc length [m], lane index (0 rightmost), speed.
    lane_change: optional (vehicle, start_s, duration_s, lane_to) with a linear lateral blend.
    """
    s0 = np.asarray(s0_m, dtype)
    lanes = np.asarray(lane)
    v = np.asarray(speed_mps, dtype)
    t = np.arange(num_frames, dtype=dtype)[:, None] * dt_s
    s = s0[None, :] + v[None, :] * t
    d = np.broadcast_to((lanes + 0.5) * LANE_M, s.shape).astype(dtype).copy()
    lane_tv = np.broadcast_to(lanes, s.shape).copy()
    if lane_change is not None:
        k, start, duration, lane_to = lane_change
        u = np.clip((t[:, 0] - start) / duration, 0.0, 1.0)
        d[:, k] = (lanes[k] + 0.5 + u * (lane_to - lanes[k])) * LANE_M
        lane_tv[:, k] = np.floor(d[:, k] / LANE_M).astype(int)
    nv = s0.shape[0]
    zeros = np.zeros_like(s)
    return Scene(
        s_m=jnp.asarray(s), d_m=jnp.asarray(d), x_m=jnp.asarray(s), y_m=jnp.asarray(d),
        heading_rad=jnp.asarray(zeros), road_angle_rad=jnp.asarray(zeros),
        speed_mps=jnp.asarray(np.broadcast_to(v, s.shape).copy()), lane=jnp.asarray(lane_tv, jnp.int32),
        length_m=jnp.full((nv,), 4.5, dtype), width_m=jnp.full((nv,), 1.8, dtype),
        kind=jnp.zeros((nv,), jnp.int32), role=jnp.asarray(np.minimum(np.arange(nv), 5), jnp.int32),
        present=jnp.ones((nv,), bool), dt_s=dt_s,
    )
