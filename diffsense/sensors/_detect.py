"""One entry point for any sensor, single scene or a batch of scenes (vmap at the edge)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from diffsense.runtime import InputError
from diffsense.scene import Scene
from diffsense.sensors._camera import camera_detect, camera_p_detect
from diffsense.sensors._config import CameraConfig, RadarConfig
from diffsense.sensors._datatypes import Detections
from diffsense.sensors._gates import Mode
from diffsense.sensors._measure import KeyOrNoise, measurement_noise
from diffsense.sensors._params import CameraParams, RadarParams
from diffsense.sensors._radar import radar_detect, radar_p_detect

Params = RadarParams | CameraParams
Config = RadarConfig | CameraConfig


def _pick(params: Params, config: Config):
    if isinstance(config, RadarConfig) and isinstance(params, RadarParams):
        return radar_detect, radar_p_detect
    if isinstance(config, CameraConfig) and isinstance(params, CameraParams):
        return camera_detect, camera_p_detect
    raise InputError(
        f"sensor parameters {type(params).__name__} do not match config {type(config).__name__}"
    )


def detect(
    scene: Scene, params: Params, config: Config, key: KeyOrNoise, *, mode: Mode = "soft",
    temperature: float | Float[Array, ""] = 1.0,
) -> Detections:
    """The sensor described by (`params`, `config`) looking at `scene` [T, V].

    `mode` "soft" gives detection probabilities differentiable in every parameter; "hard" the
    0/1 detections. `key` fixes the measurement-noise draws (common random numbers across
    parameters); it may instead be the draws themselves, [2, T, V] from
    `measurement_noise(key, scene)`, to draw once outside a loop over parameters.
    `temperature` scales all soft-gate temperatures of `config`.
    """
    sensor_detect, _ = _pick(params, config)
    return sensor_detect(scene, params, config, key, mode=mode, temperature=temperature)


def p_detect(
    scene: Scene, params: Params, config: Config, *, mode: Mode = "soft",
    temperature: float | Float[Array, ""] = 1.0,
) -> Float[Array, "T V"]:
    """Only the detection probabilities of `detect` (no noise draws)."""
    _, sensor_p = _pick(params, config)
    return sensor_p(scene, params, config, mode=mode, temperature=temperature)


def detect_batch(
    scenes: Scene, params: Params, config: Config, key: KeyOrNoise, *, mode: Mode = "soft",
    temperature: float | Float[Array, ""] = 1.0,
) -> Detections:
    """`detect` over a batch of scenes [N, T, V] with shared parameters; one noise key each.

    Scene n draws its noise from `jax.random.fold_in(key, n)` (with the default threefry keys
    exactly the draws of `detect(scenes[n], ..., fold_in(key, n))`). `key` may instead be the
    draws themselves, [N, 2, T, V] from `measurement_noise(key, scenes)`.
    """
    noise = key if jnp.issubdtype(key.dtype, jnp.floating) else measurement_noise(key, scenes)
    return jax.vmap(
        lambda scene, draws: detect(scene, params, config, draws, mode=mode, temperature=temperature)
    )(scenes, noise)
