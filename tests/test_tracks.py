"""Tracks: fill policies (soft == hard at p in {0,1}, hard == plain definitions), frames, grid."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.scene import TARGET_INDEX
from diffsense.sensors._datatypes import Detections
from diffsense.tracks import (
    build_inputs,
    fill_window,
    grid_slots,
    ground_truth_detections,
    prediction_frames,
    true_future,
)
from tests._synthetic import straight_scene


def _reference_fill(z, mask, policy):
    """Plain-loop definitions of the hard policies on one window z [W, 2], mask [W] bool."""
    out = np.zeros_like(z)
    idx = np.flatnonzero(mask)
    for k in range(len(z)):
        if mask[k]:
            out[k] = z[k]
        elif policy == "zero" or len(idx) == 0:
            out[k] = 0.0
        elif policy == "hold":
            prev = idx[idx < k]
            out[k] = z[prev[-1]] if len(prev) else 0.0
        else:
            prev, nxt = idx[idx < k], idx[idx > k]
            if len(prev) and len(nxt):
                a, b = prev[-1], nxt[0]
                out[k] = z[a] + (z[b] - z[a]) * (k - a) / (b - a)
            else:
                out[k] = z[prev[-1]] if len(prev) else z[nxt[0]]
    return out


@pytest.mark.parametrize("policy", ["zero", "hold", "interp"])
def test_hard_fill_matches_definition(policy):
    rng = np.random.default_rng(0)
    z = rng.normal(size=(64, 31, 2)) * 10
    mask = rng.random((64, 31)) < 0.5
    mask[0] = False  # a window with no detection at all
    mask[1] = True
    mask[2, :5] = False
    got = jax.jit(fill_window, static_argnums=2)(jnp.asarray(z), jnp.asarray(mask, z.dtype), policy)
    want = np.stack([_reference_fill(z[i], mask[i], policy) for i in range(64)])
    np.testing.assert_allclose(np.asarray(got), want, atol=1e-10)


@pytest.mark.parametrize("policy", ["zero", "hold", "interp"])
def test_soft_fill_is_continuous_in_p_with_finite_gradient(policy):
    rng = np.random.default_rng(1)
    z = jnp.asarray(rng.normal(size=(31, 2)))
    mask = jnp.asarray(rng.random(31) < 0.4, jnp.float64)

    hard = fill_window(z, mask, policy)
    for eps in (1e-3, 1e-6):
        # p within eps of the 0/1 pattern: the soft fill is within O(eps) of the hard one.
        near = mask * (1 - eps) + (1 - mask) * eps
        gap = float(jnp.max(jnp.abs(fill_window(z, near, policy) - hard)))
        assert gap < 100 * eps * float(jnp.max(jnp.abs(z)))
    for p_value in (0.0, 0.3, 1.0):
        g = jax.grad(lambda p: jnp.sum(fill_window(z, p, policy)))(jnp.full(31, p_value))
        assert np.all(np.isfinite(np.asarray(g)))


def test_fill_gradient_matches_finite_differences():
    rng = np.random.default_rng(2)
    z = jnp.asarray(rng.normal(size=(31, 2)))
    p0 = jnp.asarray(rng.uniform(0.05, 0.95, 31))
    w = jnp.asarray(rng.normal(size=(31, 2)))
    for policy in ("zero", "hold", "interp"):
        loss = lambda p: jnp.sum(w * fill_window(z, p, policy))  # noqa: E731
        g = jax.grad(loss)(p0)
        direction = jnp.asarray(rng.normal(size=31))
        h = 1e-6
        fd = (loss(p0 + h * direction) - loss(p0 - h * direction)) / (2 * h)
        np.testing.assert_allclose(float(g @ direction), float(fd), rtol=1e-6)


def test_prediction_frames_and_too_short_scene():
    frames = prediction_frames(201)
    assert frames[0] == 30 and frames[-1] == 150 and np.all(np.diff(frames) == 2)
    with pytest.raises(ValueError, match="too short"):
        prediction_frames(60)


def _scene():
    # ego (lane 1), target ahead-left (lane 2), a vehicle ahead of the target, one far away.
    return straight_scene(
        s0_m=[0.0, 20.0, 40.0, 300.0], lane=[1, 2, 2, 1], speed_mps=[25.0, 24.0, 24.0, 25.0]
    )


def test_ground_truth_inputs_are_exact_relative_positions():
    scene = _scene()
    frames = jnp.asarray(prediction_frames(scene.num_frames))
    inp = jax.jit(build_inputs, static_argnums=3)(scene, ground_truth_detections(scene), frames, "hold")
    # The target's last history point is the origin; 3 s ago it was 72 m behind at 24 m/s.
    np.testing.assert_allclose(np.asarray(inp.hist[:, -1]), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(inp.hist[:, 0, 0]), -72.0, atol=1e-9)
    # Neighbours: ego (behind-right), lead of target (ahead, own lane), far vehicle (not in grid).
    assert inp.nbr_hist.shape == (len(frames), 3, 16, 2)
    np.testing.assert_array_equal(np.asarray(inp.nbr_weight[0]), [1.0, 1.0, 0.0])
    lead_offset = np.asarray(inp.nbr_hist[0, 1, -1])
    np.testing.assert_allclose(lead_offset, [20.0, 0.0], atol=1e-9)
    fut = true_future(scene, frames)
    np.testing.assert_allclose(np.asarray(fut[:, -1, 0]), 24.0 * 5.0, atol=1e-9)


def test_grid_slots_follow_the_reference_layout():
    scene = _scene()
    frames = jnp.asarray([30])
    slot, inside = grid_slots(scene, frames)
    cells = 13  # the CS-LSTM grid: 13 cells of 15 ft = 4.572 m
    centre = cells // 2
    # ego: right lane (2) and 20 m behind at t=3 s -> (20 + 3) m / 4.572 m ~ 5 cells back.
    ds = float(scene.s_m[30, 0] - scene.s_m[30, TARGET_INDEX])
    assert int(slot[0, 0]) == 2 * cells + int(round(ds / 4.572)) + centre
    assert int(slot[0, 2]) == 1 * cells + int(round(20.0 / 4.572)) + centre
    assert not bool(inside[0, TARGET_INDEX]) and not bool(inside[0, 3])


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
    frames = jnp.asarray([40, 60])
    gt = ground_truth_detections(scene)

    def total_weight(scale):
        det = Detections(p_detect=gt.p_detect * scale, x_m=gt.x_m, y_m=gt.y_m)
        return jnp.sum(build_inputs(scene, det, frames, "hold").nbr_weight)

    g = jax.grad(total_weight)(1.0)
    assert np.isfinite(float(g))
