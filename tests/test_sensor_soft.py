"""Soft -> hard: as the temperature shrinks, soft p_detect converges to the hard detection
everywhere except within a few temperatures of an edge (of any gate or occlusion comparison)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_sensor_scenes import make_scene

from diffsense import sensors as sensor
from diffsense.scene import CAR, TRUCK
from diffsense.sensors import _camera, _radar
from diffsense.sensors._geometry import Tracks, angular_half_width, polar, wrap_angle

EDGE = 8.0  # "a few tau": a gate at 8 tau is within sigmoid(-8) = 3.4e-4 of its indicator
TEMPERATURES = (1.0, 0.1, 0.01, 0.001)
SENSORS = {
    "radar": (_radar._radar_terms, sensor.make_params(sensor.load_config("radar"), hfov_deg=60.0)),
    "camera": (_camera._camera_terms, sensor.make_params(sensor.load_config("camera"), hfov_deg=150.0)),
}


@functools.lru_cache
def probe_grid():
    """One probe car at each point of a grid around the ego, with two fixed occluders."""
    gx, gy = np.meshgrid(np.linspace(-20.0, 140.0, 41), np.linspace(-70.0, 70.0, 29))
    g = gx.size
    x = np.stack([np.zeros(g), gx.ravel(), np.full(g, 25.0), np.full(g, 60.0)], axis=1)
    y = np.stack([np.zeros(g), gy.ravel(), np.full(g, 1.0), np.full(g, -8.0)], axis=1)
    return make_scene(x, y, length_m=[4.5, 4.5, 12.0, 4.5], width_m=[1.8, 1.8, 2.5, 1.8],
                      kind=[CAR, CAR, TRUCK, CAR])


def occlusion_edge_distance(scene, config):
    """Per (frame, vehicle): distance, in temperatures, to the nearest occlusion comparison edge.

    Edges: equal ranges of two overlapping vehicles, and the two kinks of the overlap clip.
    """
    tau = config.temperature
    tracks = Tracks.of(scene)
    r, az = polar(tracks, config.mount_x_m)
    half = angular_half_width(tracks, r, az, config.mount_x_m).T
    r, az = r.T, az.T  # [T, V]
    hi, hj = half[:, :, None], half[:, None, :]
    reach = hi + hj - jnp.abs(wrap_angle(az[:, None, :] - az[:, :, None]))
    cap = 2 * jnp.minimum(hi, hj)
    ov_tau = jnp.deg2rad(tau.overlap_deg)
    near = jnp.abs(r[:, None, :] - r[:, :, None]) / tau.near_m
    kinks = jnp.minimum(jnp.abs(reach), jnp.abs(reach - cap)) / ov_tau
    overlapping = reach > -EDGE * ov_tau
    dist = jnp.minimum(kinks, jnp.where(overlapping, near, jnp.inf))
    v = r.shape[-1]
    occluder = (jnp.arange(v) > 0)[:, None] & ~jnp.eye(v, dtype=bool)
    return jnp.min(jnp.where(occluder, dist, jnp.inf), axis=1)


@functools.partial(jax.jit, static_argnames=("name",))
def soft_hard_and_edge(scene, params, temperature, *, name):
    terms, _ = SENSORS[name]
    config = sensor.load_config(name)
    soft = sensor.p_detect(scene, params, config, mode="soft", temperature=temperature)
    hard = sensor.p_detect(scene, params, config, mode="hard")
    gates = terms(Tracks.of(scene), params, config, "hard", 1.0)[0]
    edge = jnp.min(jnp.stack([jnp.abs(m).T / (t * temperature) for m, t in gates]), axis=0)
    edge = jnp.minimum(edge, occlusion_edge_distance(scene, config) / temperature)
    return soft[:, 1:], hard[:, 1:], edge[:, 1:]


@pytest.mark.parametrize("name", ["radar", "camera"])
def test_soft_converges_to_hard_away_from_edges(name):
    params = SENSORS[name][1]
    errors, near_edge = [], []
    for temperature in TEMPERATURES:
        soft, hard, edge = map(np.asarray, soft_hard_and_edge(probe_grid(), params, temperature, name=name))
        away = edge > EDGE
        assert np.max(np.abs(soft - hard)[away]) < 5e-3, temperature
        errors.append(np.mean(np.abs(soft - hard)))
        near_edge.append(np.mean(~away))
    assert all(a > b for a, b in zip(errors, errors[1:])), errors
    assert near_edge[-1] < 0.01, near_edge
    assert errors[-1] < 0.01, errors
    # the hard detections are not trivial: both detected and missed probes exist
    assert 0.05 < np.mean(hard) < 0.95
