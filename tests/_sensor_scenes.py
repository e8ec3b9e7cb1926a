"""Hand-built scenes and small helpers for the sensor tests (no dependence on the scene engine)."""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense import config as cfg
from diffsense import sensors
from diffsense.scene import CAR, Scene


def make_scene(x_m, y_m, *, heading_rad=None, length_m=4.5, width_m=1.8, kind=CAR,
               present=True, dtype=np.float64) -> Scene:
    """A straight-road scene (road angle 0) from world positions [T, V]; vehicle 0 is the ego."""
    x = np.atleast_2d(np.asarray(x_m, dtype))
    y = np.broadcast_to(np.asarray(y_m, dtype), x.shape)
    t, v = x.shape
    heading = np.zeros((t, v), dtype) if heading_rad is None else np.broadcast_to(
        np.asarray(heading_rad, dtype), x.shape)
    zeros = np.zeros((t, v), dtype)
    return Scene(
        s_m=jnp.asarray(x), d_m=jnp.asarray(y), x_m=jnp.asarray(x), y_m=jnp.asarray(y),
        heading_rad=jnp.asarray(heading), road_angle_rad=jnp.asarray(zeros),
        speed_mps=jnp.asarray(zeros), lane=jnp.zeros((t, v), jnp.int32),
        length_m=jnp.asarray(np.broadcast_to(np.asarray(length_m, dtype), (v,))),
        width_m=jnp.asarray(np.broadcast_to(np.asarray(width_m, dtype), (v,))),
        kind=jnp.asarray(np.broadcast_to(np.asarray(kind), (v,)), jnp.int32),
        role=jnp.asarray(np.minimum(np.arange(v), 5), jnp.int32),
        present=jnp.asarray(np.broadcast_to(np.asarray(present), (v,))),
    )


def ahead(config, ranges_m, azimuths_deg=0.0, **kw) -> Scene:
    """One frame per range: the ego at the origin and one car at (range, azimuth) from the sensor
    mounted `config.mount_x_m` ahead of it."""
    r = np.atleast_1d(np.asarray(ranges_m, float))
    az = np.radians(np.broadcast_to(azimuths_deg, r.shape))
    x = np.stack([np.zeros(len(r)), config.mount_x_m + r * np.cos(az)], axis=1)
    y = np.stack([np.zeros(len(r)), r * np.sin(az)], axis=1)
    return make_scene(x, y, **kw)


def traffic_scene(num_frames=20, dtype=np.float64) -> Scene:
    """Ego, target and five neighbours on a three-lane straight road, plus one padding slot."""
    x0 = np.array([0.0, 30.0, 55.0, 20.0, -15.0, 60.0, 90.0, 0.0])
    y0 = np.array([0.0, 3.7, 3.7, -3.7, 3.7, 0.0, -3.7, 0.0])
    speed = np.array([25.0, 24.0, 26.0, 27.0, 25.0, 23.0, 24.0, 0.0])
    t = np.arange(num_frames)[:, None] * 0.1
    x = x0 + speed * t
    y = np.broadcast_to(y0, x.shape).copy()
    y[:, 1] = 3.7 - 3.7 * np.clip(t[:, 0] / max(t[-1, 0], 1e-9), 0, 1)  # target cuts in
    kinds = np.array([0, 0, 2, 1, 0, 0, 0, 0])
    present = np.array([True] * 7 + [False])
    return make_scene(x, y, kind=kinds, present=present, dtype=dtype)


# Partial occlusion: frame i holds a car 40 m ahead of the sensor and an occluder 20 m ahead,
# shifted sideways so that it covers COVERED[i] of the car's angular interval (visible 71, 61,
# 59 and 41 %, either side of the camera's 0.6).
COVERED = (0.29, 0.39, 0.41, 0.59)


def interval(sensor_x, x, y, length=4.5, width=1.8):
    """Angular interval (lo, hi) [rad] of a heading-0 car centred at (x, y) seen from (sensor_x, 0):
    its footprint's corners projected across the line of sight, at the centre's range."""
    dx, dy = x - sensor_x, y
    bearing, r = math.atan2(dy, dx), math.hypot(dx, dy)
    across = np.array([-math.sin(bearing), math.cos(bearing)])
    corners = np.array([[sx * length / 2, sy * width / 2] for sx in (-1, 1) for sy in (-1, 1)])
    proj = corners @ across
    half = math.atan(0.5 * (proj.max() - proj.min()) / r)
    return bearing - half, bearing + half


def covered(sensor_x, target, occluder) -> float:
    """The fraction of the target's angular interval the occluder's covers (both (x, y) centres)."""
    lo_t, hi_t = interval(sensor_x, *target)
    lo_o, hi_o = interval(sensor_x, *occluder)
    return max(0.0, min(hi_t, hi_o) - max(lo_t, lo_o)) / (hi_t - lo_t)


def occlusion_scene(sensor_x) -> Scene:
    """The frames of COVERED, solved for the occluder's offset with the corner reference above."""
    from scipy.optimize import brentq

    target = (sensor_x + 40.0, 0.0)
    ys = [brentq(lambda y: covered(sensor_x, target, (sensor_x + 20.0, y)) - f, 0.0, 3.0, xtol=1e-12)
          for f in COVERED]
    x = np.array([[0.0, sensor_x + 20.0, target[0]]] * len(ys))
    return make_scene(x, np.array([[0.0, yo, 0.0] for yo in ys]))


def assert_temperature_scales_the_config(terms, tracks, config, temperature, gate, vehicle, least):
    """A sensor's `temperature` acts as every soft-gate temperature of its config (occlusion's
    included) multiplied by it: the soft gates of `terms` at `temperature` equal those of the
    scaled config at 1; and the margin of gate `gate` of `vehicle` (frame 0) moves by more than
    `least` between the config scaled by 2 and by 1/2 (the scene is sensitive)."""
    got = terms(tracks, config.params, config, "soft", temperature)[0]
    want = terms(tracks, config.params, scaled(config, temperature), "soft", 1.0)[0]
    for (m_got, t_got), (m_want, t_want) in zip(got, want, strict=True):
        np.testing.assert_allclose(np.asarray(m_got), np.asarray(m_want), rtol=1e-12, atol=1e-12)
        assert float(t_got) == pytest.approx(float(t_want), rel=1e-12)
    margin = {f: float(terms(tracks, config.params, scaled(config, f), "soft", 1.0)[0][gate][0][vehicle, 0])
              for f in (2.0, 0.5)}
    assert abs(margin[2.0] - margin[0.5]) > least, margin


def scaled(config, factor):
    """`config` with every soft-gate temperature multiplied by `factor`."""
    t = config.temperature
    return cfg.replace(config, temperature=dataclasses.replace(
        t, **{f.name: getattr(t, f.name) * factor for f in dataclasses.fields(t)}))


def sigmoid(z):
    return 1.0 / (1.0 + math.exp(-z))


def phi(z):
    """The standard normal distribution function."""
    return 0.5 * math.erfc(-z / math.sqrt(2.0))


# Compiled once per (shape, config, mode) and shared by the sensor tests: eager JAX compiles
# every primitive separately, which is far slower on the test machine.
jit_p_detect = jax.jit(sensors.p_detect, static_argnames=("config", "mode"))
jit_detect = jax.jit(sensors.detect, static_argnames=("config", "mode"))
