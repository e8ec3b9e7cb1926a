"""Gradients of soft detections and measurements: against finite differences (float64), and
finite at the extremes of every parameter, temperature and geometry (float32 and float64)."""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _laws import threshold_config
from _sensor_scenes import make_scene

from diffsense import sensors as sensor
from diffsense.scene import CAR, TRUCK

KEY = jax.random.key(3, impl="rbg")  # threefry compiles ~3 s slower on CPU
# Points where every parameter matters (no gate saturated for all vehicles): the camera at
# 120 deg resolves a car only to ~110 m, so its pixel gate is live near the 100 m range edge.
# The mounting is turned and moved off its defaults (0 deg, 4.2 / 2.5 m ahead, 0 m aside), so that
# its derivatives are taken away from the exact zeros the defaults hold.
POINTS = {
    "radar": {"hfov_deg": 30.0, "vfov_deg": 15.0, "range_m": 100.0, "tx_power_dbm": 14.0,
              "noise_figure_db": 4.8, "yaw_deg": 3.0, "mount_x_m": 4.0, "mount_y_m": 0.3},
    "camera": {"hfov_deg": 120.0, "range_m": 100.0, "width_px": 1280.0, "baseline_m": 0.12,
               "yaw_deg": -2.0, "mount_x_m": 2.2, "mount_y_m": -0.2},
}


def gradient_scene(dtype=np.float64):
    """Vehicles near each edge: FOV (15 deg), range (100 m), SNR/pixels (far), occlusion."""
    az = np.radians([14.0, -60.0, 2.0, 0.5, 0.0, 40.0])
    r = np.array([40.0, 30.0, 98.0, 106.0, 60.0, 20.0])
    x = np.r_[0.0, 4.2 + r * np.cos(az)]
    y = np.r_[0.0, r * np.sin(az)]
    frames = np.stack([x + 0.7 * t for t in range(3)])
    return make_scene(frames, np.broadcast_to(y, frames.shape), length_m=4.5, width_m=1.8,
                      kind=[CAR, CAR, CAR, TRUCK, CAR, CAR, CAR], dtype=dtype)


def objective(params, scene, config, temperature):
    det = sensor.detect(scene, params, config, KEY, temperature=temperature)
    w = jnp.linspace(0.5, 1.5, det.p_detect.size).reshape(det.p_detect.shape)
    return (jnp.sum(w * det.p_detect) + 0.01 * jnp.sum(w * det.x_m)
            + 0.01 * jnp.sum(w[::-1] * det.y_m))


value_and_grad = jax.jit(jax.value_and_grad(objective), static_argnames="config")
value = jax.jit(objective, static_argnames="config")


@pytest.mark.parametrize("name", ["radar", "camera"])
def test_gradient_matches_central_differences_for_every_parameter(name):
    config = threshold_config(name)
    params = sensor.make_params(config, **POINTS[name])
    scene = gradient_scene()
    temperature = 2.0  # wide enough that every parameter's gates are live
    _, grad = value_and_grad(params, scene, config, temperature)
    for spec in sensor.param_specs(name, config):
        r = getattr(params, spec.name)
        h = 1e-5 * abs(r)
        up = value(sensor.with_param(params, spec.name, r + h), scene, config, temperature)
        down = value(sensor.with_param(params, spec.name, r - h), scene, config, temperature)
        fd = float(up - down) / (2 * h)
        g = float(getattr(grad, spec.name))
        assert abs(fd) > 1e-4 / abs(r), f"{spec.name}: saturated, the check would be empty"
        assert g == pytest.approx(fd, rel=1e-5), spec.name


def extreme_settings(name):
    """Parameter sets at the extremes: the issue's HFOV and range values x temperatures, and
    every other parameter at both ends of its domain."""
    specs = sensor.param_specs(name)
    base = {s.name: s.default for s in specs}
    rows = []
    for hfov in (0.01, 1.0, 180.0, 270.0, 360.0):
        for range_m in (0.1, 1000.0):
            for temperature in (1e-4, 1e-2, 1.0, 10.0):
                rows.append((base | {"hfov_deg": hfov, "range_m": range_m}, temperature))
    for s in specs:
        for v in (s.lower + 1e-3 if s.lower_open else s.lower, s.upper):
            rows.append((base | {s.name: v}, 1.0))
    params = {k: np.array([row[k] for row, _ in rows]) for k in base}
    temps = np.array([t for _, t in rows])
    return params, temps


def extreme_scene(dtype):
    """Ego; a car exactly on the 30 deg FOV edge; one co-located with the radar and one with
    the camera; one behind the sensors; a car fully hidden behind a truck; a car 2 km away;
    a padding slot."""
    edge = math.radians(15.0)
    x = [0.0, 4.2 + 50 * math.cos(edge), 4.2, 2.5, -30.0, 30.0, 45.0, 2000.0, 0.0]
    y = [0.0, 50 * math.sin(edge), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    return make_scene([x, x], [y, y], length_m=[4.5, 4.5, 4.5, 4.5, 4.5, 16.0, 4.5, 4.5, 0.0],
                      width_m=[1.8, 1.8, 1.8, 1.8, 1.8, 2.6, 1.8, 1.8, 0.0],
                      kind=[CAR, CAR, CAR, CAR, CAR, TRUCK, CAR, CAR, CAR],
                      present=[True] * 8 + [False], dtype=dtype)


def _value_and_grad(scene, config, mode):
    def one(p, t):
        def f(p, t):
            det = sensor.detect(scene, p, config, KEY, mode=mode, temperature=t)
            return jnp.sum(det.p_detect) + jnp.sum(det.x_m) + jnp.sum(det.y_m), det
        (val, det), grads = jax.value_and_grad(f, argnums=(0, 1), has_aux=True)(p, t)
        return val, det, grads
    return jax.vmap(one)


@functools.partial(jax.jit, static_argnames="config")
def at_extremes(params, temps, scene, config):
    """Soft value, detections and gradients on the extreme scene and on the empty scene (ego
    only), and the hard p_detect on the extreme scene, for every parameter set."""
    empty = jax.tree.map(lambda a: a[..., :1], scene)
    hard = jax.vmap(lambda p: sensor.p_detect(scene, p, config, mode="hard"))(params)
    return (_value_and_grad(scene, config, "soft")(params, temps),
            _value_and_grad(empty, config, "soft")(params, temps), hard)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("name", ["radar", "camera"])
def test_values_and_gradients_are_finite_at_the_extremes(name, dtype):
    config = threshold_config(name)
    raw, temps = extreme_settings(name)
    params = type(config.params)(**{k: jnp.asarray(v, dtype) for k, v in raw.items()})
    soft, empty, hard = at_extremes(params, jnp.asarray(temps, dtype), extreme_scene(dtype),
                                     config)
    for leaf in jax.tree.leaves((soft, empty, hard)):
        assert leaf.dtype == dtype
        assert np.all(np.isfinite(np.asarray(leaf))), name
    for p in (soft[1].p_detect, empty[1].p_detect, hard):
        assert np.all((np.asarray(p) >= 0) & (np.asarray(p) <= 1))
    np.testing.assert_array_equal(empty[1].p_detect, 1.0)  # the ego alone
    hard_p = np.asarray(hard)
    assert set(np.unique(hard_p)) <= {0.0, 1.0}
    # Only a full circle, or a sensor turned to look back (yaw at its +-180 deg extremes), sees
    # straight behind.
    narrower = (raw["hfov_deg"] < 360.0) & (np.abs(raw["yaw_deg"]) < 90.0)
    assert np.all(hard_p[narrower][:, :, 4] == 0)  # behind both sensors
    if name == "camera":
        assert np.all(hard_p[:, :, 6] == 0)  # hidden behind the truck
