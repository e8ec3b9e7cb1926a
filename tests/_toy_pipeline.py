"""A tiny differentiable stand-in sensor and predictor, to test the objective on its own.

The sensor sees vehicles within a range r of the ego (soft: a logistic gate of width tau x 2 m)
with position noise of fixed standard-normal draws; the predictor extrapolates the target's
constant velocity and is nudged by its occupied neighbours.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from diffsense.scene import Scene
from diffsense.sensors._datatypes import Detections
from diffsense.tracks import PredictorInputs
from tests._synthetic import straight_scene

NOISE_M = 0.3


TOY_GAIN = 0.01


def toy_scenes(n: int = 3, num_frames: int = 101) -> tuple[Scene, np.ndarray]:
    scenes = [
        straight_scene(
            s0_m=[0.0, 25.0 + 5 * k, 45.0 + 7 * k, 80.0 - 3 * k],
            lane=[1, 2, 2, 1],
            speed_mps=[25.0, 24.0 + k, 24.5, 25.5],
            num_frames=num_frames,
            lane_change=(1, 3.0 + k, 4.0, 1),
        )
        for k in range(n)
    ]
    batch = jax.tree.map(lambda *a: jnp.stack(a), *scenes)
    return batch, np.arange(n) % 2


def toy_detect():
    def detect(scenes: Scene, r, tau, mode, key):
        dist = jnp.abs(scenes.x_m - scenes.x_m[..., :1])
        margin = r - dist
        if mode == "soft":
            p = jax.nn.sigmoid(margin / (2.0 * tau))
        else:
            p = (margin > 0).astype(dist.dtype)
        p = p.at[..., 0].set(1.0)
        eps = jax.random.normal(key, (2, *scenes.x_m.shape), dist.dtype)
        scale = NOISE_M * (1.0 + 0.002 * r)  # noise grows slowly with r: a real trade-off
        noisy_x = scenes.x_m + scale * eps[0]
        noisy_y = scenes.y_m + scale * eps[1]
        noisy_x = noisy_x.at[..., 0].set(scenes.x_m[..., 0])
        noisy_y = noisy_y.at[..., 0].set(scenes.y_m[..., 0])
        return Detections(p_detect=p, x_m=noisy_x, y_m=noisy_y)

    return detect


def toy_predict(gain, inputs: PredictorInputs):
    """`gain` [] scales the social nudge: the stand-in's one 'weight'."""
    velocity = (inputs.hist[:, -1] - inputs.hist[:, -6]) / 1.0  # [B, 2] per second (5 points = 1 s)
    steps = jnp.arange(1, 26, dtype=inputs.hist.dtype) * 0.2
    social = jnp.einsum("bm,bmd->bd", inputs.nbr_weight, inputs.nbr_hist[:, :, -1]) * gain
    return inputs.hist[:, -1][:, None] + (velocity + social)[:, None] * steps[None, :, None]
