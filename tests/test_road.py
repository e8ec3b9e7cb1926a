"""Road geometry: Frenet <-> Cartesian round trip, road angle = centreline derivative, gradients."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.runtime._errors import InputError
from diffsense.scene import (
    cartesian_to_frenet,
    centreline_xy,
    curvature_1pm,
    frenet_to_cartesian,
    lane_centre_d_m,
    lane_index,
    load_road,
    road_angle_rad,
)

ROADS = ("us101", "straight")


@pytest.fixture(scope="module", params=ROADS)
def road(request):
    return load_road(request.param)


def _grid(road, dtype, n=600):
    rng = np.random.default_rng(0)
    s = rng.uniform(-30.0, road.length_m + 30.0, n)
    d = rng.uniform(-3.0, road.width_m + 3.0, n)
    s[:6] = [0.0, 120.0, 280.0, 360.0, 520.0, road.length_m]  # piece joints of us101, ends
    return jnp.asarray(s, dtype), jnp.asarray(d, dtype)


@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32])
def test_round_trip_within_a_millimetre(road, dtype):
    s, d = _grid(road, dtype)
    x, y, _ = jax.jit(frenet_to_cartesian)(road, s, d)
    s2, d2 = jax.jit(cartesian_to_frenet)(road, x, y)
    assert x.dtype == s2.dtype == d2.dtype == dtype  # follows its input
    assert float(jnp.max(jnp.abs(s2 - s))) < 1e-3
    assert float(jnp.max(jnp.abs(d2 - d))) < 1e-3
    if dtype == jnp.float64:
        assert float(jnp.max(jnp.abs(s2 - s))) < 1e-8


def test_road_angle_is_the_centreline_derivative(road):
    s = jnp.linspace(-20.0, road.length_m + 20.0, 777, dtype=jnp.float64)
    tangent = jax.jit(jax.vmap(jax.jacfwd(lambda q: jnp.stack(centreline_xy(road, q)))))(s)  # [S, 2]
    assert np.allclose(jnp.linalg.norm(tangent, axis=-1), 1.0, atol=1e-12)  # s is arc length
    angle = jax.jit(road_angle_rad)(road, s)
    assert np.allclose(jnp.arctan2(tangent[:, 1], tangent[:, 0]), angle, atol=1e-12)
    h = 1e-4  # and by finite differences, independent of autodiff
    xp, yp = centreline_xy(road, s + h)
    xm, ym = centreline_xy(road, s - h)
    assert np.allclose(jnp.arctan2(yp - ym, xp - xm), angle, atol=1e-6)
    # ... and the curvature is the road angle's derivative (away from the pieces' joints).
    kappa = jax.jit(curvature_1pm)(road, s)
    fd = (road_angle_rad(road, s + h) - road_angle_rad(road, s - h)) / (2 * h)
    joint = np.min(np.abs(np.asarray(s)[:, None] - np.asarray(road.start_s_m)[None, :]), axis=1) < 2 * h
    assert np.allclose(kappa[~joint], fd[~joint], atol=1e-9)


def test_us101_bends_and_straight_does_not():
    us101, straight = load_road("us101"), load_road("straight")
    assert (us101.num_lanes, us101.auxiliary_lanes, us101.lane_width_m, us101.length_m) == (6, 1, 3.66, 640.0)
    angle = np.degrees(np.asarray(road_angle_rad(us101, jnp.linspace(0.0, 640.0, 641))))
    assert angle.max() - angle.min() > 5.0  # a documented, gentle S-bend
    assert np.all(np.abs(np.diff(angle)) < 0.1)  # gentle: < 0.1 deg per metre
    assert np.all(road_angle_rad(straight, jnp.linspace(0.0, 1000.0, 11)) == 0.0)


def test_lanes(road):
    lanes = jnp.arange(road.num_lanes)
    d = jax.jit(lane_centre_d_m)(road, lanes)
    assert np.allclose(d, (np.arange(road.num_lanes) + 0.5) * road.lane_width_m)
    assert np.array_equal(jax.jit(lane_index)(road, d), lanes)
    assert int(lane_index(road, -5.0)) == 0 and int(lane_index(road, 1e3)) == road.num_lanes - 1


def test_gradients_match_finite_differences():
    road = load_road("us101")
    # Points on a bend, on a straight piece and near a joint; d left and right of the lanes.
    pts = jnp.array([[200.0, 5.0], [60.0, 12.0], [280.3, 20.0], [450.0, -1.0]], jnp.float64)

    def both(p):
        x, y, th = frenet_to_cartesian(road, p[0], p[1])
        s, d = cartesian_to_frenet(road, x + 0.3, y - 0.2)
        return jnp.stack([x, y, th, s, d])

    jvp = jax.jit(jax.vmap(lambda p, t: jax.jvp(both, (p,), (t,)), in_axes=(0, None)))  # compiled once
    jac = jnp.stack([jvp(pts, e)[1] for e in jnp.eye(2)], axis=-1)  # [P, 5, 2]
    h = 1e-5
    fd = jnp.stack([(jvp(pts + h * e, e)[0] - jvp(pts - h * e, e)[0]) / (2 * h) for e in jnp.eye(2)], axis=-1)
    assert np.all(np.isfinite(jac))
    assert np.allclose(jac, fd, atol=1e-6), (jac, fd)


@pytest.mark.parametrize(
    "text, needle",
    [
        ('name = "r"\nlane_width_m = 3.66\nnum_lanes = 3\nlanes = 2\n[[segments]]\nlength_m = 10.0\n', "unknown key 'lanes'"),
        ('name = "r"\nlane_width_m = "wide"\nnum_lanes = 3\n[[segments]]\nlength_m = 10.0\n', "lane_width_m: expected a number"),
        ('name = "r"\nlane_width_m = 3.66\nnum_lanes = 3\n[[segments]]\nlength_m = 10.0\nradius_m = 5.0\n', "radius_m"),
        ('name = "r"\nlane_width_m = 3.66\nnum_lanes = 3\nsegments = []\n', "needs 1 to 7 segments"),
    ],
)
def test_road_config_rejects(tmp_path, text, needle):
    path = tmp_path / "road.toml"
    path.write_text(text)
    with pytest.raises(InputError, match=needle):
        load_road(path)


def test_unknown_road_lists_the_known_ones():
    with pytest.raises(InputError, match="known: straight, us101"):
        load_road("autobahn")
