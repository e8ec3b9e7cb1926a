"""A tiny differentiable stand-in sensor and predictor, to test the objective on its own.

They are also the test suite's example of plugging into the protocols: `ToySensor` is a
`diffsense.sensors.Sensor` defined outside the package, `ToyPredictor` a
`diffsense.predictors.Predictor`. The sensor sees vehicles within `range_m` of the ego (soft: a
logistic gate of width tau x 2 m) with position noise of fixed standard-normal draws; the
predictor extrapolates the target's constant velocity and is nudged by its occupied neighbours.
"""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from diffsense import config as cfg
from diffsense.metrics import EstimatorConfig, make_objective
from diffsense.predictors import CSLSTM_SPEC, InputSpec, PredictorInputs
from diffsense.scene import Scene
from diffsense.sensors import Camera, Detections, ParamSpec, Radar, Sensor
from diffsense.tracks import build_inputs, flatten_instants, prediction_frames
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
    scenes, scenario = toy_scenes(n)
    frames = prediction_frames(scenes.num_frames)[:instants]
    return make_objective(scenes, scenario, frames, ToySensor(), ToyPredictor(jnp.asarray(TOY_GAIN)),
                          names=("range_m",), key=key, **kwargs)


LAWS = Path(__file__).resolve().parents[1] / "configs" / "sensors" / "laws"
# The shipped radar with the Swerling-1 detection law: its detections are random events.
SWERLING = Radar.from_toml(LAWS / "radar_swerling1.toml")
# The radar and camera with the deterministic threshold law (the paper profile's): 0/1 detections.
THRESHOLD_RADAR = Radar.from_toml(LAWS / "radar_threshold.toml")
THRESHOLD_CAMERA = Camera.from_toml(LAWS / "camera_threshold.toml")
H = "hfov_deg"


def with_pfa(radar: Radar, pfa: float) -> Radar:
    """`radar` with another false-alarm probability of its detection law."""
    return Radar(cfg.replace(radar.config, detection=cfg.replace(radar.config.detection, pfa=pfa)))


def radar_objective(radar=SWERLING, key=None, draws=4, n=1, kind="mean-field", **knobs):
    """E(hfov_deg) of `radar` and the toy predictor over `n` toy scenes, 3 instants each."""
    scenes, scenario = toy_scenes(n)
    frames = prediction_frames(scenes.num_frames)[:3]
    return make_objective(scenes, scenario, frames, radar, ToyPredictor(jnp.asarray(TOY_GAIN)), names=(H,),
                          key=key, estimator=EstimatorConfig(kind=kind, reference_draws=draws, **knobs), shard=False)


def predictions(E, det: Detections) -> jax.Array:
    """E's predictor on tracks built from detections `det` [N, T, V]: [N, I, F, 2] [m], through
    the public tracks functions (independent of the objective's own path)."""
    frames = jnp.asarray(E.frames)
    inputs = jax.vmap(lambda s, d: build_inputs(s, d, frames, E.fill, E.spec))(E.data.scenes, det)
    return E.predictor(flatten_instants(inputs)).reshape(E.data.gt_pred.shape)


def eq12_of(E, det: Detections) -> jax.Array:
    """Eq. 12's E^2 [m^2] of detections `det`: the variant-weighted mean of the mean over instants
    and horizon steps of the squared distance to the ground-truth-input prediction."""
    sq = jnp.sum((predictions(E, det) - E.data.gt_pred) ** 2, axis=-1)
    return jnp.sum(E.data.weight * jnp.mean(sq, axis=(1, 2))) / jnp.sum(E.data.weight)


def float32(scenes: Scene) -> Scene:
    """`scenes` with every float array in float32."""
    return jax.tree.map(lambda a: a.astype(jnp.float32) if jnp.issubdtype(a.dtype, jnp.floating) else a, scenes)
