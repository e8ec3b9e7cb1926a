"""From a sensor's per-vehicle model to `Detections`: ego and padding rules, common-random noise.

Noise uses common random numbers: the standard-normal draws are fixed by the key (one pair per
frame and vehicle, for range and azimuth) and only their scale depends on the parameters r, so
every quantity that depends on r is a smooth, deterministic function of it.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from diffsense.scene import EGO_INDEX, Scene
from diffsense.sensor._datatypes import Detections
from diffsense.sensor._gates import check_mode, p_from_gates
from diffsense.sensor._geometry import to_world


def own_and_padding(scene: Scene, p: Float[Array, "T V"]) -> Float[Array, "T V"]:
    """p with the ego set to 1 (its own state is known) and padding vehicles to 0."""
    p = jnp.where(scene.present[..., None, :] != 0, p, 0.0)
    return p.at[..., EGO_INDEX].set(1.0)


def standard_normals(key: PRNGKeyArray, scene: Scene, dtype) -> Float[Array, "2 T V"]:
    """The fixed draws (range, azimuth) for every frame and vehicle of `scene`."""
    return jax.random.normal(key, (2, *scene.x_m.shape), dtype=dtype)


def detections(
    scene: Scene,
    mount_x_m: float,
    p: Float[Array, "T V"],
    range_m: Float[Array, "T V"],
    azimuth_rad: Float[Array, "T V"],
    range_sigma_m: Float[Array, "T V"],
    azimuth_sigma_rad: Float[Array, "T V"],
    key: PRNGKeyArray,
) -> Detections:
    """Noisy sensor-frame measurements converted to world `Detections` with the ego pose."""
    noise = standard_normals(key, scene, range_m.dtype)
    x, y = to_world(
        scene,
        mount_x_m,
        range_m + range_sigma_m * noise[0],
        azimuth_rad + azimuth_sigma_rad * noise[1],
    )
    known = jnp.arange(scene.x_m.shape[-1]) == EGO_INDEX
    known = known | (scene.present[..., None, :] == 0)
    x = jnp.where(known, scene.x_m, x)
    y = jnp.where(known, scene.y_m, y)
    return Detections(p_detect=own_and_padding(scene, p), x_m=x, y_m=y)


def p_detect_of(terms, scene: Scene, params, config, mode: str, temperature) -> Float[Array, "T V"]:
    """p_detect of a sensor given its `terms` function (gates, range, azimuth, noise scales)."""
    mode = check_mode(mode)
    gates = terms(scene, params, config, mode, temperature)[0]
    return own_and_padding(scene, p_from_gates(gates, mode))


def detect_of(terms, scene: Scene, params, config, key: PRNGKeyArray, mode: str,
              temperature) -> Detections:
    """`Detections` of a sensor given its `terms` function."""
    mode = check_mode(mode)
    gates, range_m, azimuth_rad, range_sigma, azimuth_sigma = terms(
        scene, params, config, mode, temperature)
    return detections(scene, config.mount_x_m, p_from_gates(gates, mode), range_m, azimuth_rad,
                      range_sigma, azimuth_sigma, key)
