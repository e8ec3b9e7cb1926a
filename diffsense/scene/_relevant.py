"""The scene's relevant vehicles: what can reach the target's social grid, and what can hide it.

A scene decides the size of the computation (only what a scene requires is modelled): a
vehicle is kept when, in some frame of a 3 s history window, it is in the target's 13 x 3 social
grid (its lane within one of the target's and its longitudinal offset within 6.5 cells of 15 ft,
the CS-LSTM grid), or when it can occlude such a vehicle (or the target) from the ego's sensors.
The occlusion test is conservative: a vehicle whose body overlaps the road-frame box spanned by
the ego (sensors up to `sensor_reach_m` ahead of its centre) and the hidden vehicle's body,
widened by `margin_m` for the road's curvature, may occlude it.
Everything else (far background traffic) is dropped, and the kept vehicles are padded only to the
largest count in the batch, so the cost downstream does not grow with far traffic.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Int

from diffsense.runtime import call
from diffsense.scene._datatypes import BACKGROUND, CAR, EGO_INDEX, TARGET_INDEX, Scene

# The road-frame box must contain the straight sight line, which bows in (s, d) on a bend by the
# sagitta of a 100 m chord (the sensors' range) on the tightest shipped bend, R = 1200 m:
# 100^2 / (8 * 1200) = 1.04 m.
MARGIN_M = 1.1
# Pads sit this far behind the ego, on its lane: absent, but finite and far from everything.
_PAD_BEHIND_M = 1000.0


def _window_frames(num_frames: int, frames: Int[ArrayLike, " I"] | None, dt_s: float,
                   history_s: float) -> Bool[Array, " T"]:
    """Frames inside the history window of some prediction instant (all frames if none given)."""
    xp = jnp if isinstance(frames, jax.core.Tracer) else np  # numpy: no program to look up
    if frames is None:
        return np.ones((num_frames,), bool)
    t = xp.arange(num_frames)
    f = xp.asarray(frames)
    back = round(history_s / dt_s)
    return xp.any((t[:, None] <= f[None, :]) & (t[:, None] >= f[None, :] - back), axis=-1)


def _overlap(lo_a, hi_a, lo_b, hi_b):
    return (hi_a > lo_b) & (lo_a < hi_b)


def _relevant_one(scene: Scene, window: Bool[Array, " T"], margin_m: float, sensor_reach_m: float,
                  grid_half_length_m: float) -> Bool[Array, " V"]:
    s, d, lane = scene.s_m, scene.d_m, scene.lane  # [T, V]
    half_l, half_w = 0.5 * scene.length_m, 0.5 * scene.width_m  # [V]
    in_grid = (
        (jnp.abs(lane - lane[:, TARGET_INDEX, None]) <= 1)
        & (jnp.abs(s - s[:, TARGET_INDEX, None]) < grid_half_length_m + margin_m)
        & window[:, None]
        & scene.present
    )
    index = jnp.arange(scene.num_vehicles)
    core = jnp.any(in_grid, axis=0) | (index == TARGET_INDEX)  # seen in some history window
    # Box from the ego (with its sensors) to each vehicle j, per frame: [T, V].
    e = EGO_INDEX
    box_s_lo = jnp.minimum(s[:, e, None] - half_l[e], s - half_l)
    box_s_hi = jnp.maximum(s[:, e, None] + sensor_reach_m, s + half_l)
    box_d_lo = jnp.minimum(d[:, e, None] - half_w[e], d - half_w) - margin_m
    box_d_hi = jnp.maximum(d[:, e, None] + half_w[e], d + half_w) + margin_m
    # Vehicle k (last axis) overlaps the box of j (middle axis): [T, V, V].
    hides = (
        _overlap(box_s_lo[..., None], box_s_hi[..., None], (s - half_l)[:, None, :], (s + half_l)[:, None, :])
        & _overlap(box_d_lo[..., None], box_d_hi[..., None], (d - half_w)[:, None, :], (d + half_w)[:, None, :])
    )
    matters = window[:, None, None] & core[None, :, None] & (index != EGO_INDEX)[None, :, None]
    occluder = jnp.any(hides & matters, axis=(0, 1)) & (index != EGO_INDEX)
    return (core | occluder | (index == EGO_INDEX)) & scene.present


def relevant_mask(
    scene: Scene, frames: Int[ArrayLike, " I"] | None = None, *, history_s: float,
    grid_half_length_m: float, sensor_reach_m: float, margin_m: float = MARGIN_M,
) -> Bool[Array, "*N V"]:
    """Which vehicles are relevant (jit-able): [V] for a scene [T, V], [N, V] for a batch.

    `frames`: prediction instants (frame indices); their history windows are searched. None:
    every frame (any instant may be asked for). `margin_m` widens the grid's length and the
    occlusion boxes (see MARGIN_M); `sensor_reach_m` is how far ahead of the ego's centre the
    sensors sit.
    """
    window = _window_frames(scene.num_frames, frames, scene.dt_s, history_s)
    return call(_mask, scene, window, float(margin_m), float(sensor_reach_m), float(grid_half_length_m))


def _mask(scene: Scene, window: Bool[Array, " T"], margin_m: float, sensor_reach_m: float,
          grid_half_length_m: float) -> Bool[Array, "*N V"]:
    one = lambda sc: _relevant_one(sc, window, margin_m, sensor_reach_m, grid_half_length_m)  # noqa: E731
    if scene.s_m.ndim == 2:
        return one(scene)
    return jax.lax.map(one, scene)  # one scene at a time: [T, V, V] temporaries, not [N, T, V, V]


def relevant_selection(
    scene: Scene, frames: Int[ArrayLike, " I"] | None = None, *, history_s: float,
    grid_half_length_m: float, sensor_reach_m: float, margin_m: float = MARGIN_M,
) -> tuple[np.ndarray, np.ndarray]:
    """Which vehicles `relevant_vehicles` keeps, as (order, keep) [N, K] for a batch [N, T, V]
    (or [K] for one scene): the kept vehicles' indices first, in their order, then pad slots
    (keep False). `select_vehicles(scene, order, keep)` applies it, also to a traced scene."""
    mask = np.asarray(relevant_mask(scene, frames, history_s=history_s, grid_half_length_m=grid_half_length_m,
                                    sensor_reach_m=sensor_reach_m, margin_m=margin_m))
    batched = mask.ndim == 2
    mask = mask if batched else mask[None]
    width = int(mask.sum(axis=-1).max())
    # Stable sort puts kept vehicles first in their order; the rest fill the pad slots.
    order = np.argsort(~mask, axis=-1, kind="stable")[:, :width]
    keep = np.take_along_axis(mask, order, axis=-1)
    return (order, keep) if batched else (order[0], keep[0])


def select_vehicles(scene: Scene, order: Int[ArrayLike, "*N K"], keep: Bool[ArrayLike, "*N K"]) -> Scene:
    """`scene` [*N, T, V] reduced to the selection of `relevant_selection` [*N, T, K] (jit-able)."""
    batched = scene.s_m.ndim == 3
    sc = scene if batched else jax.tree.map(lambda a: a[None], scene)
    xp = np if isinstance(order, np.ndarray) and isinstance(keep, np.ndarray) else jnp  # numpy: no program
    order, keep = (xp.asarray(order), xp.asarray(keep)) if batched else (xp.asarray(order)[None], xp.asarray(keep)[None])
    out = call(_gather, sc, order, keep)
    return out if batched else jax.tree.map(lambda a: a[0], out)


def relevant_vehicles(
    scene: Scene, frames: Int[ArrayLike, " I"] | None = None, *, history_s: float,
    grid_half_length_m: float, sensor_reach_m: float, margin_m: float = MARGIN_M,
) -> Scene:
    """The scene restricted to its relevant vehicles, in their original order (ego 0, target 1).

    The vehicle axis shrinks to the largest relevant count in the batch; a variant with fewer
    relevant vehicles is padded with absent ones (present False, role BACKGROUND, 1 km behind the
    ego). Not jit-able as a whole (its output size depends on the data): `relevant_mask` and
    `select_vehicles` are.
    """
    order, keep = relevant_selection(scene, frames, history_s=history_s, grid_half_length_m=grid_half_length_m,
                                     sensor_reach_m=sensor_reach_m, margin_m=margin_m)
    return select_vehicles(scene, order, keep)


def _gather(scene: Scene, order: Int[Array, "N K"], keep: Bool[Array, "N K"]) -> Scene:
    per_frame = lambda a: jnp.take_along_axis(a, order[:, None, :], axis=-1)  # noqa: E731
    per_vehicle = lambda a: jnp.take_along_axis(a, order, axis=-1)  # noqa: E731
    keep_t = keep[:, None, :]
    ego = lambda a: a[..., EGO_INDEX : EGO_INDEX + 1]  # noqa: E731
    back = _PAD_BEHIND_M
    angle = ego(scene.road_angle_rad)
    fill = dict(
        s_m=ego(scene.s_m) - back, d_m=ego(scene.d_m), x_m=ego(scene.x_m) - back * jnp.cos(angle),
        y_m=ego(scene.y_m) - back * jnp.sin(angle), heading_rad=ego(scene.heading_rad),
        road_angle_rad=angle, speed_mps=ego(scene.speed_mps), lane=ego(scene.lane),
    )
    frame_fields = {k: jnp.where(keep_t, per_frame(getattr(scene, k)), v) for k, v in fill.items()}
    return Scene(
        **frame_fields,
        length_m=jnp.where(keep, per_vehicle(scene.length_m), ego(scene.length_m)),
        width_m=jnp.where(keep, per_vehicle(scene.width_m), ego(scene.width_m)),
        kind=jnp.where(keep, per_vehicle(scene.kind), CAR),
        role=jnp.where(keep, per_vehicle(scene.role), BACKGROUND),
        present=keep & per_vehicle(scene.present),
        dt_s=scene.dt_s,
    )
