"""From a sensor's per-vehicle model to `Detections`: ego and padding rules, common-random noise.

Noise uses common random numbers: the standard-normal draws are fixed by the key (one pair per
frame and vehicle, for range and azimuth) and only their scale depends on the parameters r, so
every quantity that depends on r is a smooth, deterministic function of it. The draws can also be
made once with `measurement_noise` and passed instead of the key, so that a loop over r does not
regenerate them.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from diffsense import runtime
from diffsense.runtime import InputError
from diffsense.scene import EGO_INDEX, Scene
from diffsense.sensors._datatypes import Detections
from diffsense.sensors._gates import check_mode, check_temperature, p_from_gates
from diffsense.sensors._geometry import Tracks, to_world
from diffsense.sensors._mount import mount_of
from diffsense.sensors._weather import CLEAR

KeyOrNoise = PRNGKeyArray | Float[Array, "2 T V"]


def measurement_noise(key: PRNGKeyArray, scene: Scene) -> Float[Array, "*N 2 T V"]:
    """The standard-normal draws (range, azimuth) of `detect` / `detect_batch` for `key`.

    One scene [T, V] gives [2, T, V]; a batch [N, T, V] gives [N, 2, T, V], scene n drawn from
    `jax.random.fold_in(key, n)`. Dtype: that of the scene's positions.
    """
    shape, dtype = scene.x_m.shape, scene.x_m.dtype
    if len(shape) == 2:
        return runtime.normal(key, (2, *shape), dtype)
    if len(shape) == 3:
        keys = jax.vmap(lambda n: jax.random.fold_in(key, n))(jnp.arange(shape[0]))
        return jax.vmap(lambda k: runtime.normal(k, (2, *shape[1:]), dtype))(keys)
    raise InputError(f"a scene has positions [T, V] or [N, T, V], got shape {shape}")


def _noise(key_or_noise: KeyOrNoise, scene: Scene) -> Float[Array, "2 T V"]:
    if jnp.issubdtype(key_or_noise.dtype, jnp.floating):
        expected = (2, *scene.x_m.shape)
        if key_or_noise.shape != expected:
            raise InputError(f"measurement noise has shape {key_or_noise.shape}, expected {expected}")
        return key_or_noise.astype(scene.x_m.dtype)
    return measurement_noise(key_or_noise, scene)


def tracks_of(scene: Scene) -> Tracks:
    if scene.x_m.ndim != 2:
        raise InputError(f"one scene [T, V] expected, got positions of shape {scene.x_m.shape} "
                         "(use detect_batch for a batch)")
    return Tracks.of(scene)


def own_and_padding(tracks: Tracks, p: Float[Array, "V T"]) -> Float[Array, "T V"]:
    """p [T, V] with the ego set to 1 (its own state is known) and padding vehicles to 0."""
    p = jnp.where(tracks.present, p, 0.0)
    return _transposed(p.at[EGO_INDEX].set(1.0))


def _transposed(a: Float[Array, "V T"]) -> Float[Array, "T V"]:
    # The barrier keeps XLA from fusing the transpose into the math above, which would run it
    # in the [T, V] layout (vehicle axis minor) that vectorises badly on CPU.
    return jax.lax.optimization_barrier(a).T


def p_detect_of(terms, scene: Scene, params, config, mode: str, temperature, weather=CLEAR) -> Float[Array, "T V"]:
    """p_detect of a sensor given its `terms` function (gates, range, azimuth, noise scales)."""
    mode = check_mode(mode)
    check_temperature(temperature)
    tracks = tracks_of(scene)
    gates = terms(tracks, params, config, mode, temperature, weather)[0]
    return own_and_padding(tracks, p_from_gates(gates, mode))


def detect_of(terms, scene: Scene, params, config, key_or_noise: KeyOrNoise, mode: str,
              temperature, weather=CLEAR) -> Detections:
    """`Detections` of a sensor given its `terms` function: noisy sensor-frame measurements
    converted to the world with the ego pose."""
    mode = check_mode(mode)
    check_temperature(temperature)
    tracks = tracks_of(scene)
    noise = jax.lax.optimization_barrier(jnp.swapaxes(_noise(key_or_noise, scene), -1, -2))
    gates, range_m, _, range_sigma, azimuth_sigma = terms(tracks, params, config, mode, temperature, weather)
    x, y = to_world(tracks, mount_of(params, config), range_m + range_sigma * noise[0],
                    azimuth_sigma * noise[1])
    known = (jnp.arange(x.shape[0]) == EGO_INDEX)[:, None] | ~tracks.present
    x = jnp.where(known, tracks.x_m, x)
    y = jnp.where(known, tracks.y_m, y)
    return Detections(p_detect=own_and_padding(tracks, p_from_gates(gates, mode)),
                      x_m=_transposed(x), y_m=_transposed(y))
