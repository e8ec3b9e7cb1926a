"""The predictor's inputs and the true future are in the road's curvilinear frame.

On a bend, a vehicle that keeps its lane has no lateral motion in the road frame; a frame rotated
by the road angle at t would show the bend as a lateral drift of travel^2 / (2 R) (2.3 m after 75 m
on R = 1200 m), which no predictor trained on straight-road coordinates can forecast.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from diffsense.scene import TARGET_INDEX, Scene
from diffsense.sensors import Detections
from diffsense.tracks import build_inputs, ground_truth_detections, true_future

RADIUS_M = 300.0
SPEED_MPS = 15.0
T0 = 40  # prediction instant (frame): 3 s of history before it, 5 s of future after it


def _arc_scene(num_frames: int = 100) -> Scene:
    """Ego (lane 0) and target (lane 1, 30 m ahead) keeping their lanes on a left bend of radius
    300 m that starts at the origin heading +x: the reference line is (R sin(s/R), R (1 - cos(s/R))),
    offset d to the left. The target is at s = 90 m (road angle 0.3 rad) at frame T0."""
    t = np.arange(num_frames)[:, None] * 0.1
    s = np.array([0.0, 30.0])[None, :] + SPEED_MPS * t
    d = np.broadcast_to(np.array([0.5 * 3.66, 1.5 * 3.66]), s.shape).copy()
    theta = s / RADIUS_M
    x = RADIUS_M * np.sin(theta) - d * np.sin(theta)
    y = RADIUS_M * (1.0 - np.cos(theta)) + d * np.cos(theta)
    f = lambda a: jnp.asarray(a, jnp.float64)
    return Scene(
        s_m=f(s), d_m=f(d), x_m=f(x), y_m=f(y), heading_rad=f(theta), road_angle_rad=f(theta),
        speed_mps=f(np.full(s.shape, SPEED_MPS)), lane=jnp.asarray(np.broadcast_to([0, 1], s.shape), jnp.int32),
        length_m=f([4.5, 4.5]), width_m=f([1.8, 1.8]), kind=jnp.zeros(2, jnp.int32),
        role=jnp.asarray([0, 1], jnp.int32), present=jnp.ones(2, bool), dt_s=0.1,
    )


def test_lane_keeping_on_a_bend_has_no_lateral_motion():
    scene = _arc_scene()
    assert TARGET_INDEX == 1
    fut = np.asarray(true_future(scene, jnp.asarray([T0]))[0])  # [25, 2]
    steps = np.arange(1, 26) * 0.2
    np.testing.assert_allclose(fut[:, 0], SPEED_MPS * steps, atol=1e-9)  # 3, 6, ... 75 m along the road
    np.testing.assert_allclose(fut[:, 1], 0.0, atol=1e-9)  # a frame rotated at t shows the bend as drift
    hist = np.asarray(build_inputs(scene, ground_truth_detections(scene), jnp.asarray([T0]), "hold").hist[0])
    np.testing.assert_allclose(hist[:, 0], -SPEED_MPS * np.arange(15, -1, -1) * 0.2, atol=1e-9)
    np.testing.assert_allclose(hist[:, 1], 0.0, atol=1e-9)


def test_a_measurement_error_is_turned_into_the_road_frame_at_the_vehicle():
    """An error of (2, 1) m in world (x, y), measured where the road points 0.3 rad left of +x
    (the target at t), is 2 cos 0.3 + sin 0.3 = 2.206193 m ahead along the road and -2 sin 0.3 +
    cos 0.3 = 0.364296 m to the left of it; 1 s earlier, 15 m back on the bend, the road points
    0.25 rad left: 2.185229 m and 0.474105 m."""
    scene = _arc_scene()
    np.testing.assert_allclose(float(scene.road_angle_rad[T0, TARGET_INDEX]), 0.3, atol=1e-12)
    gt = ground_truth_detections(scene)
    frames = jnp.asarray([T0 - 10, T0])
    det = Detections(p_detect=gt.p_detect, x_m=gt.x_m.at[frames, TARGET_INDEX].add(2.0),
                     y_m=gt.y_m.at[frames, TARGET_INDEX].add(1.0))
    hist = np.asarray(build_inputs(scene, det, jnp.asarray([T0]), "hold").hist[0])
    np.testing.assert_allclose(hist[-1], [2.206193185, 0.364296076], atol=1e-8)
    np.testing.assert_allclose(hist[10], [-15.0 + 2.185228803, 0.474104503], atol=1e-8)
    # the rest of the history is untouched by the error
    np.testing.assert_allclose(np.delete(hist[:, 1], [10, 15]), 0.0, atol=1e-9)
