"""Tracks pinned by hand: soft fills as expectations over detection patterns, and the 10 Hz ->
5 Hz history with a missed detection on a kept and on a dropped frame.

tests/test_tracks.py pins the hard fills to plain-loop definitions and the history's two ends;
these pin the soft values and every point in between.
"""

from __future__ import annotations

import dataclasses
import itertools

import jax
import numpy as np
import pytest

from diffsense.scene import TARGET_INDEX
from diffsense.sensors._datatypes import Detections
from diffsense.tracks import (PredictorInputs, build_inputs, flatten_instants, ground_truth_detections,
                             prediction_frames, true_future)
from diffsense.tracks._fill import fill_window
from tests._synthetic import straight_scene


def _hard_fill(z, seen, policy):
    """A missed point's value for one detection pattern, by scanning outwards from it."""
    out = z.copy()
    for k in np.flatnonzero(~seen):
        before = [i for i in range(k - 1, -1, -1) if seen[i]][:1]
        after = [i for i in range(k + 1, len(z)) if seen[i]][:1]
        if policy == "zero" or not (before or after):
            out[k] = 0.0
        elif policy == "hold":
            out[k] = z[before[0]] if before else 0.0
        elif before and after:
            a, b = before[0], after[0]
            out[k] = ((b - k) * z[a] + (k - a) * z[b]) / (b - a)
        else:
            out[k] = z[(before or after)[0]]
    return out


def _expectation(z, p, policy):
    """E[filled window] over all 2^W independent detection patterns with probabilities p."""
    total = np.zeros_like(z)
    for pattern in itertools.product((False, True), repeat=len(p)):
        seen = np.array(pattern)
        total += np.prod(np.where(seen, p, 1 - p)) * _hard_fill(z, seen, policy)
    return total


@pytest.mark.parametrize("policy", ["zero", "hold"])
def test_soft_zero_and_hold_are_exact_expectations(policy):
    rng = np.random.default_rng(3)
    z, p = rng.normal(size=(7, 2)) * 10, rng.uniform(0.05, 0.95, 7)
    np.testing.assert_allclose(np.asarray(fill_window(z, p, policy)), _expectation(z, p, policy),
                               atol=1e-12)


def test_soft_hold_by_hand():
    # z = 1, 2, 3 with p = 1, 1/2, 1/2: the last point is 3 (p 1/2), else 2 (1/4), else 1 (1/4).
    got = np.asarray(fill_window(np.array([[1.0, 0], [2, 0], [3, 0]]), np.array([1, 0.5, 0.5]), "hold"))
    np.testing.assert_allclose(got[:, 0], [1.0, 1.5, 2.25])


def test_soft_interp_weights_below_one_by_hand():
    # The soft interp's recurrences (diffsense/tracks/_fill.py) on z = 2, 6 m with p = 1/2, 1/2.
    # Forward holds F, any-detection h, steps-since a: F0 = 1, h0 = 1/2, a0 = 1/2; backward
    # (from the right) B0 = 1/2 * 2 + 1/2 * (1/2 * 6) = 5/2, h'0 = 3/4, b0 = 3/4. At k = 0 the
    # weights b0 h0 + a0 h'0 = 3/8 + 3/8 = 3/4 (below 1, as no hard pattern gives), the fill
    # (b0 F0 + a0 B0) / (3/4) = (3/4 + 5/4) / (3/4) = 8/3, and the point 1/2 * 2 + 1/2 * 8/3 = 7/3 m.
    got = np.asarray(fill_window(np.array([[2.0, 0.0], [6.0, 0.0]]), np.array([0.5, 0.5]), "interp"))
    np.testing.assert_allclose(got[0], [7.0 / 3.0, 0.0], rtol=1e-12)


@pytest.mark.xfail(strict=True, reason=(
    "soft interp blends the uncertain point's own measurement into its fill (the forward and "
    "backward holds at k include p_k z_k): 4.25 instead of 0.5 * 4 + 0.5 * 5 = 4.5"))
def test_soft_interp_single_uncertain_point():
    # Detections at 0 and 10 m for sure, the middle one (measured 4 m) with p = 1/2: missed, it
    # is interpolated to 5 m, so its expectation is 0.5 * 4 + 0.5 * 5 = 4.5 m.
    z = np.array([[0.0, 0.0], [4.0, 0.0], [10.0, 0.0]])
    got = np.asarray(fill_window(z, np.array([1.0, 0.5, 1.0]), "interp"))
    np.testing.assert_allclose(got[1, 0], 4.5)


# Ego and a target 20 m ahead in the same lane, the target at 24 m/s: at 10 Hz it moves 2.4 m a
# frame, so its 16-point 5 Hz history at t is lon = -4.8 m * (15, 14, ..., 0), lat = 0.
T0 = 40  # the prediction instant (frame)
TRUE_HIST = -4.8 * np.arange(15, -1, -1)
_build = jax.jit(build_inputs, static_argnums=3)


def _history(p_target_by_frame, fill):
    scene = straight_scene(s0_m=[0.0, 20.0], lane=[1, 1], speed_mps=[25.0, 24.0])
    gt = ground_truth_detections(scene)
    p = gt.p_detect
    for frame, value in p_target_by_frame.items():
        p = p.at[frame, TARGET_INDEX].set(value)
    inputs = _build(scene, Detections(p_detect=p, x_m=gt.x_m, y_m=gt.y_m),
                    jax.numpy.asarray([T0]), fill)
    return np.asarray(inputs.hist[0]), np.asarray(true_future(scene, jax.numpy.asarray([T0]))[0])


def test_history_is_16_points_at_5_hz_and_future_25_points():
    hist, future = _history({}, "zero")
    np.testing.assert_allclose(hist[:, 0], TRUE_HIST, atol=1e-9)
    np.testing.assert_allclose(hist[:, 1], 0.0, atol=1e-9)
    np.testing.assert_allclose(future[:, 0], 4.8 * np.arange(1, 26), atol=1e-9)


@pytest.mark.parametrize("fill, kept_point", [
    ("zero", 0.0),      # a missed point is the target's own position at t
    ("hold", -26.4),    # the last 10 Hz detection, 1.1 s before t: -24 * 1.1
    ("interp", -24.0),  # halfway between 0.9 s and 1.1 s before t: exact for constant speed
])
def test_fill_happens_at_10_hz_before_downsampling(fill, kept_point):
    # Missed: frame t - 10 (1.0 s, kept as history point 10) and t - 5 (0.5 s, dropped at 5 Hz).
    hist, _ = _history({T0 - 10: 0.0, T0 - 5: 0.0}, fill)
    want = TRUE_HIST.copy()
    want[10] = kept_point
    np.testing.assert_allclose(hist[:, 0], want, atol=1e-9)
    # Soft: p = 1/2 at t - 10 gives the average of the detected and the filled value.
    soft, _ = _history({T0 - 10: 0.5}, fill)
    assert soft[10, 0] == pytest.approx(0.5 * (-24.0) + 0.5 * kept_point, abs=1e-9)


def test_prediction_frames_at_the_edges():
    # CS-LSTM at 10 Hz: 30 history frames (15 points x 2) before t, 50 future frames after it.
    # The shortest scene, 81 frames, has exactly one instant; one frame more at stride 1 has two.
    np.testing.assert_array_equal(prediction_frames(81), [30])
    np.testing.assert_array_equal(prediction_frames(82, stride_frames=1), [30, 31])
    np.testing.assert_array_equal(prediction_frames(85, stride_frames=2), [30, 32, 34])
    with pytest.raises(ValueError, match="needs at least 81"):
        prediction_frames(80)


def test_a_5_hz_scene_feeds_one_frame_per_point():
    # At 5 Hz a predictor point is one frame: history t-15 ... t, future t+1 ... t+25 (5 s).
    scene = straight_scene(s0_m=[0.0, 20.0], lane=[1, 1], speed_mps=[25.0, 24.0], num_frames=41, dt_s=0.2)
    frames = prediction_frames(41, stride_frames=1, scene_dt_s=0.2)
    np.testing.assert_array_equal(frames, [15])
    future = np.asarray(true_future(scene, jax.numpy.asarray(frames))[0])
    np.testing.assert_allclose(future[:, 0], 4.8 * np.arange(1, 26), atol=1e-9)
    hist = np.asarray(build_inputs(scene, ground_truth_detections(scene), jax.numpy.asarray(frames), "hold").hist[0])
    np.testing.assert_allclose(hist[:, 0], 4.8 * np.arange(-15, 1), atol=1e-9)


def test_flatten_instants_puts_scene_major_rows_first():
    # [N=2 scenes, I=3 instants, ...] -> [6, ...], row n * 3 + i holding scene n's instant i.
    n, i = 2, 3
    tag = np.arange(n * i, dtype=float).reshape(n, i)
    inputs = PredictorInputs(hist=np.broadcast_to(tag[:, :, None, None], (n, i, 16, 2)),
                             nbr_hist=np.broadcast_to(tag[:, :, None, None, None], (n, i, 4, 16, 2)),
                             nbr_slot=np.zeros((n, i, 4), np.int32), nbr_weight=np.ones((n, i, 4)))
    flat = flatten_instants(inputs)
    assert flat.hist.shape == (6, 16, 2) and flat.nbr_hist.shape == (6, 4, 16, 2)
    assert flat.nbr_slot.shape == flat.nbr_weight.shape == (6, 4)
    np.testing.assert_array_equal(np.asarray(flat.hist)[:, 0, 0], [0, 1, 2, 3, 4, 5])
    np.testing.assert_array_equal(np.asarray(flat.nbr_hist)[:, 2, 7, 1], [0, 1, 2, 3, 4, 5])


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_ground_truth_detects_the_present_vehicles_in_the_scene_dtype(dtype):
    # A float32 run stays float32 (under x64 a default float would be float64).
    scene = straight_scene(s0_m=[0.0, 20.0, 40.0], lane=[1, 1, 2], speed_mps=[25.0] * 3, num_frames=3, dtype=dtype)
    scene = dataclasses.replace(scene, present=jax.numpy.asarray([True, True, False]))
    det = ground_truth_detections(scene)
    assert det.p_detect.dtype == dtype
    np.testing.assert_array_equal(np.asarray(det.p_detect), [[1.0, 1.0, 0.0]] * 3)


def test_a_miss_at_the_instant_is_never_filled_from_the_future():
    # Missed at t itself: interp has no later detection in the window, so it holds t - 0.1 s
    # (-2.4 m); the detection at t + 0.1 s (+2.4 m) lies in the future and must not be used.
    hist, _ = _history({T0: 0.0}, "interp")
    assert hist[-1, 0] == pytest.approx(-2.4, abs=1e-9)


def test_lateral_offsets_are_positive_to_the_left():
    # Target in lane 1; the ego one lane right (lane 0), 10 m behind; a car one lane left, 8 m ahead.
    scene = straight_scene(s0_m=[0.0, 10.0, 18.0], lane=[0, 1, 2], speed_mps=[25.0] * 3)
    inputs = build_inputs(scene, ground_truth_detections(scene), jax.numpy.asarray([T0]), "hold")
    np.testing.assert_allclose(np.asarray(inputs.nbr_hist[0, :, -1]), [[-10.0, -3.66], [8.0, 3.66]], atol=1e-9)
    future = np.asarray(true_future(scene, jax.numpy.asarray([T0]))[0])
    np.testing.assert_allclose(future[:, 1], 0.0, atol=1e-9)


def test_a_measurement_error_enters_the_road_frame_rotated_by_the_road_angle():
    # Road at 0.3 rad; the target measured (2, 1) m off in world x, y at every frame. In the road
    # frame: lon = 2 cos 0.3 + sin 0.3 = 2.206192 m, lat = -2 sin 0.3 + cos 0.3 = 0.364297 m.
    scene = straight_scene(s0_m=[0.0, 20.0], lane=[1, 1], speed_mps=[25.0, 24.0])
    scene = dataclasses.replace(scene, road_angle_rad=scene.road_angle_rad + 0.3)
    gt = ground_truth_detections(scene)
    det = Detections(p_detect=gt.p_detect, x_m=gt.x_m.at[:, TARGET_INDEX].add(2.0),
                     y_m=gt.y_m.at[:, TARGET_INDEX].add(1.0))
    hist = np.asarray(build_inputs(scene, det, jax.numpy.asarray([T0]), "hold").hist[0])
    np.testing.assert_allclose(hist[-1], [2.206192, 0.364297], atol=1e-6)


def _grid_scene():
    # Target (lane 1) at 50 m; others: the ego, cars 6 cells behind and ahead (-27.432, +27.432 m,
    # the grid's first and last cells), one 7 cells ahead (outside), one two lanes left (outside).
    return straight_scene(s0_m=[0.0, 50.0, 22.568, 77.432, 82.004, 55.0], lane=[0, 1, 1, 2, 1, 3],
                          speed_mps=[25.0] * 6)


def test_grid_edges_slots_and_their_type():
    scene = _grid_scene()
    inputs = build_inputs(scene, ground_truth_detections(scene), jax.numpy.asarray([T0]), "hold")
    # Slot = grid lane (0 left, 1 own, 2 right) x 13 + cell (0 = 6 cells behind); ego: right, 50 m
    # behind, outside the 13 cells.
    assert inputs.nbr_slot.dtype == np.int32
    np.testing.assert_array_equal(np.asarray(inputs.nbr_weight[0]), [0.0, 1.0, 1.0, 0.0, 0.0])
    np.testing.assert_array_equal(np.asarray(inputs.nbr_slot[0])[1:3], [13 + 0, 0 * 13 + 12])


def test_neighbour_weight_is_seen_at_t_for_zero_and_at_least_once_for_hold():
    scene = _grid_scene()
    gt = ground_truth_detections(scene)
    # The car behind (vehicle 2): missed at t, detected with p 1/2 at t - 1, t - 2 and t - 29 (the
    # window's second frame), else missed: seen at least once with p 1 - 1/8.
    p = gt.p_detect.at[:, 2].set(0.0).at[T0 - 1, 2].set(0.5).at[T0 - 2, 2].set(0.5).at[T0 - 29, 2].set(0.5)
    det = Detections(p_detect=p, x_m=gt.x_m, y_m=gt.y_m)
    weight = {fill: float(build_inputs(scene, det, jax.numpy.asarray([T0]), fill).nbr_weight[0, 1])
              for fill in ("zero", "hold", "interp")}
    assert weight == pytest.approx({"zero": 0.0, "hold": 0.875, "interp": 0.875}, abs=1e-12)


def test_the_grid_follows_the_predictor_spec():
    # A coarser grid than the CS-LSTM's: 5 cells of 20 m, cell = round(ds / 20 m) + 2. Vehicle 2
    # (27.432 m behind): round(-1.37) = -1, cell 1; vehicle 3 (27.432 m ahead, left lane): cell 3;
    # vehicle 4 (32.004 m ahead): round(1.6) = 2, cell 4, inside now; the ego (50 m behind, right
    # lane): round(-2.5) = -2 (half to even), cell 0, inside too; vehicle 5 two lanes left: outside.
    from diffsense.predictors import CSLSTM_SPEC

    spec = dataclasses.replace(CSLSTM_SPEC, grid_cells=5, grid_cell_m=20.0)
    scene = _grid_scene()
    inputs = build_inputs(scene, ground_truth_detections(scene), jax.numpy.asarray([T0]), "hold", spec)
    np.testing.assert_array_equal(np.asarray(inputs.nbr_weight[0]), [1.0, 1.0, 1.0, 1.0, 0.0])
    # slot = grid lane (0 left, 1 own, 2 right) x 5 + cell
    np.testing.assert_array_equal(np.asarray(inputs.nbr_slot[0])[:4], [2 * 5 + 0, 1 * 5 + 1, 0 * 5 + 3, 1 * 5 + 4])
