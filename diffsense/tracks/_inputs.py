"""From a scene and a sensor's detections to what the CS-LSTM eats.

For every prediction instant t (a 10 Hz frame index) and the scene's vehicles:

1. Every measured point of the 3 s history window (frames t-30 .. t) is expressed in the road's
   curvilinear frame relative to the target at t: lon = s - s_target(t) along the road, lat =
   d - d_target(t) to the left. This is the frame the predictors learnt in: NGSIM's local
   coordinates run along the road, and the generated training traffic drives a straight ring in
   (s, d). A Cartesian frame rotated by the road angle at t would turn a bend into lateral motion
   the predictor cannot know of (on the US-101 segment's R = 1200 m bend, 75 m of travel is 2.3 m
   of apparent lateral drift).
2. The fill policy (`_fill.py`) turns missed detections into expected points.
3. The window is downsampled to 5 Hz: 16 points, the last one at t.
4. Neighbours are placed in the 13 x 3 social grid by their ground-truth lane and longitudinal
   offset at t; the grid occupancy of a neighbour is the probability that the sensor has it at
   all (detected at t for `zero`, detected at least once in the window for `hold`/`interp`).

Ground-truth inputs are the same code with p = 1 and no noise (`ground_truth_detections`).
The origin is the target's ground-truth pose for both inputs, so the two predictions are directly
comparable and a missing point under `zero` sits exactly at the target, as in the paper.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from diffsense.scene import SCENE_DT_S, TARGET_INDEX, Scene
from diffsense.sensors import Detections
from diffsense.tracks._fill import FillPolicy, fill_window
from diffsense.tracks._spec import CSLSTM_SPEC, InputSpec, PredictorInputs


def _frames(spec: InputSpec, scene_dt_s: float) -> tuple[int, int, int]:
    """(frames per predictor point, history frames before t, future frames after t) [-]."""
    step = spec.frames_per_point(scene_dt_s)
    return step, (spec.history_points - 1) * step, spec.future_points * step


def prediction_frames(num_frames: int, stride_frames: int = 2, spec: InputSpec = CSLSTM_SPEC,
                      scene_dt_s: float = SCENE_DT_S) -> np.ndarray:
    """Frame indices with a full history and future of `spec`, every `stride_frames` [-]."""
    _, history, future = _frames(spec, scene_dt_s)
    last = num_frames - 1 - future
    if last < history:
        raise ValueError(
            f"a scene of {num_frames} frames is too short for a {spec.history_s:g} s history and "
            f"{spec.future_s:g} s future (needs at least {history + future + 1})"
        )
    return np.arange(history, last + 1, stride_frames, dtype=np.int32)


def ground_truth_detections(scene: Scene) -> Detections:
    """A perfect sensor: every present vehicle detected at its true position."""
    p = jnp.broadcast_to(scene.present[..., None, :], scene.x_m.shape).astype(scene.x_m.dtype)
    return Detections(p_detect=p, x_m=scene.x_m, y_m=scene.y_m)


def _road_points(scene: Scene, det_x_m: Array, det_y_m: Array, window: Int[Array, "I W"]) -> Array:
    """Measured points of the frames `window` in the road frame (s, d) [I, W, V, 2] [m].

    A measurement differs from its vehicle's true position by the sensor's error (metres); that
    error is turned into the road frame at the vehicle's true pose and added to its true (s, d).
    Exact for ground truth (no error); for a measurement, the neglected term is the error times
    curvature x offset (below 1 % of the error on a highway's radii).
    """
    ex, ey = det_x_m[window] - scene.x_m[window], det_y_m[window] - scene.y_m[window]
    c, s = jnp.cos(scene.road_angle_rad[window]), jnp.sin(scene.road_angle_rad[window])
    return jnp.stack([scene.s_m[window] + c * ex + s * ey, scene.d_m[window] - s * ex + c * ey], axis=-1)


def _target_origin(scene: Scene, frames: Int[Array, " I"]) -> Float[Array, "I 2"]:
    """The target's road-frame (s, d) at each prediction instant [m]."""
    return jnp.stack([scene.s_m[frames, TARGET_INDEX], scene.d_m[frames, TARGET_INDEX]], axis=-1)


def _windows(frames: Int[Array, " I"], offsets: np.ndarray) -> Int[Array, "I W"]:
    return frames[:, None] + jnp.asarray(offsets)[None, :]


def grid_slots(scene: Scene, frames: Int[Array, " I"], spec: InputSpec = CSLSTM_SPEC) -> tuple[Int[Array, "I V"], Array]:
    """Grid id of every vehicle around the target at each instant, and whether it is in the grid.

    Lane from the ground-truth lane index (lane 0 = rightmost, so the target's left lane is
    lane + 1); cell from the longitudinal offset along the road, rounded to the spec's cells.
    """
    lane = scene.lane[frames]  # [I, V]
    ds = scene.s_m[frames] - scene.s_m[frames, TARGET_INDEX][:, None]
    lane_offset = lane - lane[:, TARGET_INDEX][:, None]  # +1 = one lane to the left
    grid_lane = 1 - lane_offset  # 0 left, 1 own, 2 right
    cells = spec.grid_cells
    cell = jnp.round(ds / spec.grid_cell_m).astype(jnp.int32) + cells // 2
    vehicle = jnp.arange(scene.num_vehicles)
    inside = (
        (jnp.abs(lane_offset) <= 1)
        & (cell >= 0)
        & (cell < cells)
        & scene.present[None, :]
        & (vehicle != TARGET_INDEX)[None, :]
    )
    slot = jnp.where(inside, grid_lane * cells + cell, 0).astype(jnp.int32)
    return slot, inside


def build_inputs(scene: Scene, det: Detections, frames: Int[Array, " I"], fill: FillPolicy,
                 spec: InputSpec = CSLSTM_SPEC) -> PredictorInputs:
    """Predictor inputs at each prediction instant of one scene (arrays [T, V]).

    `det` may carry soft probabilities (expected histories) or 0/1 detections (hard histories).
    Neighbour candidates are all vehicles but the target (M = V - 1), in vehicle order.
    """
    frames = jnp.asarray(frames)
    step, history, _ = _frames(spec, scene.dt_s)
    window = _windows(frames, np.arange(-history, 1))  # [I, W]
    # [I, W, V, 2] measured points relative to the target, and [I, W, V] probabilities.
    z = _road_points(scene, det.x_m, det.y_m, window) - _target_origin(scene, frames)[:, None, None, :]
    p = det.p_detect[window]
    # Fill along the window axis: put it next to the coordinate axis.
    z = jnp.swapaxes(z, 1, 2)  # [I, V, W, 2]
    p = jnp.swapaxes(p, 1, 2)  # [I, V, W]
    filled = fill_window(z, p, fill)[:, :, ::step]  # [I, V, H, 2]
    if fill == "zero":
        seen = p[..., -1]
    else:
        seen = 1.0 - jnp.prod(1.0 - p, axis=-1)  # detected at least once in the window
    slot, inside = grid_slots(scene, frames, spec)
    others = np.array([v for v in range(scene.num_vehicles) if v != TARGET_INDEX], dtype=np.int32)
    return PredictorInputs(
        hist=filled[:, TARGET_INDEX],
        nbr_hist=filled[:, others],
        nbr_slot=slot[:, others],
        nbr_weight=jnp.where(inside[:, others], seen[:, others], 0.0),
    )


def true_future(scene: Scene, frames: Int[Array, " I"], spec: InputSpec = CSLSTM_SPEC) -> Float[Array, "I F 2"]:
    """The target's true future (the spec's points after t) relative to it at t, road frame [m]."""
    frames = jnp.asarray(frames)
    step, _, future = _frames(spec, scene.dt_s)
    window = _windows(frames, np.arange(step, future + 1, step))
    ahead = jnp.stack([scene.s_m[window, TARGET_INDEX], scene.d_m[window, TARGET_INDEX]], axis=-1)
    return ahead - _target_origin(scene, frames)[:, None, :]


def flatten_instants(inputs: PredictorInputs) -> PredictorInputs:
    """Merge the leading (scene, instant) axes [N, I, ...] into one batch axis [N*I, ...]."""
    return jax.tree.map(lambda a: a.reshape((-1,) + a.shape[2:]), inputs)
