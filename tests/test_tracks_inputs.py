"""What the predictor eats, built from a scene and detections: the prediction instants at the
scene's edges, the 10 Hz -> 5 Hz history with missed points filled before downsampling, the true
future, the social grid's slots and occupancy, and the batch flattening, all by hand on straight
roads (the bend: tests/test_tracks_road_frame.py)."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.scene import TARGET_INDEX
from diffsense.sensors import Detections
from diffsense.tracks import (
    CSLSTM_SPEC,
    PredictorInputs,
    build_inputs,
    flatten_instants,
    grid_slots,
    ground_truth_detections,
    prediction_frames,
    true_future,
)
from tests._synthetic import straight_scene

# Ego and a target 20 m ahead in the same lane, the target at 24 m/s: at 10 Hz it moves 2.4 m a
# frame, so its 16-point 5 Hz history at t is lon = -4.8 m * (15, 14, ..., 0), lat = 0.
T0 = 40  # the prediction instant (frame)
TRUE_HIST = -4.8 * np.arange(15, -1, -1)
_build = jax.jit(build_inputs, static_argnums=3)


def _with_target_p(scene, p_target_by_frame):
    gt = ground_truth_detections(scene)
    p = gt.p_detect
    for frame, value in p_target_by_frame.items():
        p = p.at[frame, TARGET_INDEX].set(value)
    return Detections(p_detect=p, x_m=gt.x_m, y_m=gt.y_m)


def _history(p_target_by_frame, fill):
    scene = straight_scene(s0_m=[0.0, 20.0], lane=[1, 1], speed_mps=[25.0, 24.0])
    inputs = _build(scene, _with_target_p(scene, p_target_by_frame), jnp.asarray([T0]), fill)
    return np.asarray(inputs.hist[0]), np.asarray(true_future(scene, jnp.asarray([T0]))[0])


def test_prediction_frames_at_the_edges():
    # CS-LSTM at 10 Hz: 30 history frames (15 points x 2) before t, 50 future frames after it.
    # The shortest scene, 81 frames, has exactly one instant; one frame more at stride 1 has two.
    np.testing.assert_array_equal(prediction_frames(81), [30])
    np.testing.assert_array_equal(prediction_frames(82, stride_frames=1), [30, 31])
    np.testing.assert_array_equal(prediction_frames(85, stride_frames=2), [30, 32, 34])
    frames = prediction_frames(201)
    assert frames[0] == 30 and frames[-1] == 150 and np.all(np.diff(frames) == 2)
    with pytest.raises(ValueError, match="81"):
        prediction_frames(80)


def test_history_is_16_points_at_5_hz_and_future_25_points():
    hist, future = _history({}, "zero")
    np.testing.assert_allclose(hist[:, 0], TRUE_HIST, atol=1e-9)
    np.testing.assert_allclose(hist[:, 1], 0.0, atol=1e-9)
    np.testing.assert_allclose(future[:, 0], 4.8 * np.arange(1, 26), atol=1e-9)


def test_a_5_hz_scene_feeds_one_frame_per_point():
    # At 5 Hz a predictor point is one frame: history t-15 ... t, future t+1 ... t+25 (5 s).
    scene = straight_scene(s0_m=[0.0, 20.0], lane=[1, 1], speed_mps=[25.0, 24.0], num_frames=41, dt_s=0.2)
    frames = prediction_frames(41, stride_frames=1, scene_dt_s=0.2)
    np.testing.assert_array_equal(frames, [15])
    future = np.asarray(true_future(scene, jnp.asarray(frames))[0])
    np.testing.assert_allclose(future[:, 0], 4.8 * np.arange(1, 26), atol=1e-9)
    hist = np.asarray(build_inputs(scene, ground_truth_detections(scene), jnp.asarray(frames), "hold").hist[0])
    np.testing.assert_allclose(hist[:, 0], 4.8 * np.arange(-15, 1), atol=1e-9)


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


def test_a_miss_at_the_instant_is_never_filled_from_the_future():
    # Missed at t itself: interp has no later detection in the window, so it holds t - 0.1 s
    # (-2.4 m); the detection at t + 0.1 s (+2.4 m) lies in the future and must not be used.
    hist, _ = _history({T0: 0.0}, "interp")
    assert hist[-1, 0] == pytest.approx(-2.4, abs=1e-9)


def _scene():
    # ego (lane 1), target ahead-left (lane 2), a vehicle ahead of the target, one far away.
    return straight_scene(s0_m=[0.0, 20.0, 40.0, 300.0], lane=[1, 2, 2, 1], speed_mps=[25.0, 24.0, 24.0, 25.0])


def test_ground_truth_inputs_are_exact_relative_positions():
    scene = _scene()
    frames = jnp.asarray(prediction_frames(scene.num_frames))
    inp = _build(scene, ground_truth_detections(scene), frames, "hold")
    # The target's last history point is the origin; 3 s ago it was 72 m behind at 24 m/s.
    np.testing.assert_allclose(np.asarray(inp.hist[:, -1]), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(inp.hist[:, 0, 0]), -72.0, atol=1e-9)
    # Neighbours: ego (behind-right), lead of target (ahead, own lane), far vehicle (not in grid).
    assert inp.nbr_hist.shape == (len(frames), 3, 16, 2)
    np.testing.assert_array_equal(np.asarray(inp.nbr_weight[0]), [1.0, 1.0, 0.0])
    np.testing.assert_allclose(np.asarray(inp.nbr_hist[0, 1, -1]), [20.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(np.asarray(true_future(scene, frames)[:, -1, 0]), 24.0 * 5.0, atol=1e-9)


def test_lateral_offsets_are_positive_to_the_left():
    # Target in lane 1; the ego one lane right (lane 0), 10 m behind; a car one lane left, 8 m ahead.
    scene = straight_scene(s0_m=[0.0, 10.0, 18.0], lane=[0, 1, 2], speed_mps=[25.0] * 3)
    inputs = build_inputs(scene, ground_truth_detections(scene), jnp.asarray([T0]), "hold")
    np.testing.assert_allclose(np.asarray(inputs.nbr_hist[0, :, -1]), [[-10.0, -3.66], [8.0, 3.66]], atol=1e-9)
    np.testing.assert_allclose(np.asarray(true_future(scene, jnp.asarray([T0]))[0])[:, 1], 0.0, atol=1e-9)


def test_missed_target_is_penalised_not_dropped():
    scene = _scene()
    frames = jnp.asarray(prediction_frames(scene.num_frames))
    gt = ground_truth_detections(scene)
    blind = Detections(p_detect=gt.p_detect.at[:, TARGET_INDEX].set(0.0), x_m=gt.x_m, y_m=gt.y_m)
    for fill in ("zero", "hold", "interp"):
        inp = build_inputs(scene, blind, frames, fill)
        assert inp.hist.shape[0] == len(frames)
        np.testing.assert_allclose(np.asarray(inp.hist), 0.0)  # no information at all


def test_occupancy_gradient_is_finite_when_always_detected():
    scene = _scene()
    gt = ground_truth_detections(scene)

    def total_weight(scale):
        det = Detections(p_detect=gt.p_detect * scale, x_m=gt.x_m, y_m=gt.y_m)
        return jnp.sum(build_inputs(scene, det, jnp.asarray([40, 60]), "hold").nbr_weight)

    assert np.isfinite(float(jax.grad(total_weight)(1.0)))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_ground_truth_detects_the_present_vehicles_in_the_scene_dtype(dtype):
    # A float32 run stays float32 (under x64 a default float would be float64).
    scene = straight_scene(s0_m=[0.0, 20.0, 40.0], lane=[1, 1, 2], speed_mps=[25.0] * 3, num_frames=3, dtype=dtype)
    scene = dataclasses.replace(scene, present=jnp.asarray([True, True, False]))
    det = ground_truth_detections(scene)
    assert det.p_detect.dtype == dtype
    np.testing.assert_array_equal(np.asarray(det.p_detect), [[1.0, 1.0, 0.0]] * 3)


def test_grid_slots_follow_the_reference_layout():
    scene = _scene()
    slot, inside = grid_slots(scene, jnp.asarray([30]))
    cells, centre = 13, 6  # the CS-LSTM grid: 13 cells of 15 ft = 4.572 m
    # ego: right lane (2) and 20 m behind at t=3 s -> (20 + 3) m / 4.572 m ~ 5 cells back.
    ds = float(scene.s_m[30, 0] - scene.s_m[30, TARGET_INDEX])
    assert int(slot[0, 0]) == 2 * cells + int(round(ds / 4.572)) + centre
    assert int(slot[0, 2]) == 1 * cells + round(20.0 / 4.572) + centre
    assert not bool(inside[0, TARGET_INDEX]) and not bool(inside[0, 3])


def _grid_scene():
    # Target (lane 1) at 50 m; others: the ego, cars 6 cells behind and ahead (-27.432, +27.432 m,
    # the grid's first and last cells), one 7 cells ahead (outside), one two lanes left (outside).
    return straight_scene(s0_m=[0.0, 50.0, 22.568, 77.432, 82.004, 55.0], lane=[0, 1, 1, 2, 1, 3],
                          speed_mps=[25.0] * 6)


def test_grid_edges_slots_and_their_type():
    scene = _grid_scene()
    inputs = build_inputs(scene, ground_truth_detections(scene), jnp.asarray([T0]), "hold")
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
    weight = {fill: float(build_inputs(scene, det, jnp.asarray([T0]), fill).nbr_weight[0, 1])
              for fill in ("zero", "hold", "interp")}
    assert weight == pytest.approx({"zero": 0.0, "hold": 0.875, "interp": 0.875}, abs=1e-12)


def test_the_grid_follows_the_predictor_spec():
    # A coarser grid than the CS-LSTM's: 5 cells of 20 m, cell = round(ds / 20 m) + 2. Vehicle 2
    # (27.432 m behind): round(-1.37) = -1, cell 1; vehicle 3 (27.432 m ahead, left lane): cell 3;
    # vehicle 4 (32.004 m ahead): round(1.6) = 2, cell 4, inside now; the ego (50 m behind, right
    # lane): round(-2.5) = -2 (half to even), cell 0, inside too; vehicle 5 two lanes left: outside.
    spec = dataclasses.replace(CSLSTM_SPEC, grid_cells=5, grid_cell_m=20.0)
    scene = _grid_scene()
    inputs = build_inputs(scene, ground_truth_detections(scene), jnp.asarray([T0]), "hold", spec)
    np.testing.assert_array_equal(np.asarray(inputs.nbr_weight[0]), [1.0, 1.0, 1.0, 1.0, 0.0])
    # slot = grid lane (0 left, 1 own, 2 right) x 5 + cell
    np.testing.assert_array_equal(np.asarray(inputs.nbr_slot[0])[:4], [2 * 5 + 0, 1 * 5 + 1, 0 * 5 + 3, 1 * 5 + 4])


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
