"""A tiny differentiable stand-in sensor and predictor, to test the objective on its own.

They are also the test suite's example of plugging into the protocols: `ToySensor` is a
`diffsense.sensors.Sensor` defined outside the package, `ToyPredictor` a
`diffsense.predictors.Predictor`. The sensor sees vehicles within `range_m` of the ego (soft: a
logistic gate of width tau x 2 m) with position noise of fixed standard-normal draws; the
predictor extrapolates the target's constant velocity and is nudged by its occupied neighbours.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from diffsense.predictors import CSLSTM_SPEC, InputSpec, PredictorInputs
from diffsense.scene import Scene
from diffsense.sensors import Sensor
from diffsense.sensors._datatypes import Detections
from diffsense.sensors._params import ParamSpec
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


class ToySensor(Sensor):
    """Sees vehicles within range_m of the ego; its noise grows slowly with range (a trade-off)."""

    kind: ClassVar[str] = "toy"

    def param_specs(self) -> tuple[ParamSpec, ...]:
        return (ParamSpec("range_m", "m", 0.0, 1000.0, True, 50.0, "detection range"),)

    @property
    def mount_x_m(self) -> float:
        return 0.0

    def _detect(self, scene: Scene, r, noise, mode, temperature, weather) -> Detections:
        dist = jnp.abs(scene.x_m - scene.x_m[..., :1])
        margin = r["range_m"] - dist
        if mode == "soft":
            p = jax.nn.sigmoid(margin / (2.0 * temperature))
        else:
            p = (margin > 0).astype(dist.dtype)
        p = p.at[..., 0].set(1.0)
        eps = jax.random.normal(noise, (2, *scene.x_m.shape), dist.dtype)
        scale = NOISE_M * (1.0 + 0.002 * r["range_m"])
        noisy_x = (scene.x_m + scale * eps[0]).at[..., 0].set(scene.x_m[..., 0])
        noisy_y = (scene.y_m + scale * eps[1]).at[..., 0].set(scene.y_m[..., 0])
        return Detections(p_detect=p, x_m=noisy_x, y_m=noisy_y)


class ToyPredictor(eqx.Module):
    """Constant velocity from the last second, nudged by `gain` times the occupied neighbours."""

    gain: jax.Array
    spec: InputSpec = eqx.field(static=True, default=CSLSTM_SPEC)

    def __call__(self, inputs: PredictorInputs):
        velocity = (inputs.hist[:, -1] - inputs.hist[:, -6]) / 1.0  # [B, 2] per second (5 points = 1 s)
        steps = jnp.arange(1, 26, dtype=inputs.hist.dtype) * 0.2
        social = jnp.einsum("bm,bmd->bd", inputs.nbr_weight, inputs.nbr_hist[:, :, -1]) * self.gain
        return inputs.hist[:, -1][:, None] + (velocity + social)[:, None] * steps[None, :, None]


class ValidatedToyPredictor(ToyPredictor):
    """The toy predictor with a validation RMSE [m at 1..5 s] so small that every toy scene lies
    outside its domain (the domain guard then writes its note)."""

    validation_rmse_m: tuple[float, ...] = (0.01, 0.02, 0.03, 0.04, 0.05)


def toy_objective(n: int = 3, key=None, instants: int | None = None, **kwargs):
    """E(range_m) of the toy sensor and predictor over `n` toy scenes (the first `instants`
    prediction instants of each, all if None)."""
    from diffsense.metrics import make_objective
    from diffsense.tracks import prediction_frames

    scenes, scenario = toy_scenes(n)
    frames = prediction_frames(scenes.num_frames)[:instants]
    return make_objective(scenes, scenario, frames, ToySensor(), ToyPredictor(jnp.asarray(TOY_GAIN)),
                          names=("range_m",), key=key, **kwargs)
