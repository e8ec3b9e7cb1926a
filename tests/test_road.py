"""The road's geometry against circle geometry written out by hand, its lanes, its config's
limits, and the derivatives of its maps.

The road (`make_road`) chains its pieces with a chord formula (sigma sinc(kappa sigma / 2) in the
direction of the mid-chord heading); here every point comes from the circle itself instead: a
piece of curvature kappa starting at p0 with heading th0 turns about the centre
c = p0 + (-sin th0, cos th0) / kappa, and the point at (sigma, d) is
c + (1 / kappa - d) (sin th, -cos th) with th = th0 + kappa sigma. The shipped us101 road
(configs/roads/us101.toml): straight 120 m, 160 m of R = 1200 m left, straight 80 m, 160 m of
R = -1500 m right, straight 120 m.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense import scene
from diffsense.runtime import InputError

PIECES = [(120.0, 0.0), (160.0, 1.0 / 1200.0), (80.0, 0.0), (160.0, -1.0 / 1500.0), (120.0, 0.0)]


def _advance(x, y, th, length, kappa):
    """End pose of a piece of `length` and curvature `kappa` from (x, y, th): the circle, or the line."""
    if kappa == 0.0:
        return x + length * math.cos(th), y + length * math.sin(th), th
    end = th + kappa * length
    return x + (math.sin(end) - math.sin(th)) / kappa, y - (math.cos(end) - math.cos(th)) / kappa, end


def _starts(heading=0.0):
    poses = [(0.0, 0.0, heading)]
    for length, kappa in PIECES[:-1]:
        poses.append(_advance(*poses[-1], length, kappa))
    return poses


def _point(s, d, heading=0.0):
    """World (x, y, heading) of the road-frame point (s, d) on us101, by the circles."""
    edges = np.cumsum([0.0] + [p[0] for p in PIECES])
    i = int(np.clip(np.searchsorted(edges, s, side="right") - 1, 0, len(PIECES) - 1))
    x0, y0, th0 = _starts(heading)[i]
    sigma, kappa = s - edges[i], PIECES[i][1]
    if kappa == 0.0:
        th = th0
        cx, cy = x0 + sigma * math.cos(th0), y0 + sigma * math.sin(th0)
        return cx - d * math.sin(th), cy + d * math.cos(th), th
    th = th0 + kappa * sigma
    centre = (x0 - math.sin(th0) / kappa, y0 + math.cos(th0) / kappa)
    return centre[0] + (1.0 / kappa - d) * math.sin(th), centre[1] - (1.0 / kappa - d) * math.cos(th), th


@pytest.fixture(scope="module")
def us101():
    return scene.load_road("us101")


def test_the_pieces_chain_as_circles(us101):
    starts = _starts()
    pads = scene.MAX_PIECES - len(PIECES)  # zero-length straight pieces at the end's pose
    end = _advance(*starts[-1], *PIECES[-1])
    np.testing.assert_allclose(us101.start_s_m, [0.0, 120.0, 280.0, 360.0, 520.0] + [640.0] * pads, atol=1e-12)
    np.testing.assert_allclose(us101.curvature_1pm, [k for _, k in PIECES] + [0.0] * pads, atol=1e-15)
    np.testing.assert_allclose(us101.start_x_m, [p[0] for p in starts] + [end[0]] * pads, atol=1e-9)
    np.testing.assert_allclose(us101.start_y_m, [p[1] for p in starts] + [end[1]] * pads, atol=1e-9)
    np.testing.assert_allclose(us101.start_heading_rad, [p[2] for p in starts] + [end[2]] * pads, atol=1e-12)
    # the left bend turns 160 / 1200 rad, the right one back 160 / 1500 rad
    assert end[2] == pytest.approx(160.0 / 1200.0 - 160.0 / 1500.0, abs=1e-15)
    assert float(us101.length_m) == 640.0 and float(us101.width_m) == pytest.approx(6 * 3.66, abs=1e-12)
    assert (int(us101.num_lanes), int(us101.auxiliary_lanes), float(us101.lane_width_m)) == (6, 1, 3.66)


# On each piece, before the start and beyond the end, on a joint and just past one; left of the
# road's edge and right of it.
POINTS = [(-30.0, 2.0), (0.0, 0.0), (60.0, 7.3), (120.0, -1.5), (120.5, 3.0), (200.0, 5.0), (279.0, 20.0),
          (280.4, -2.0), (300.0, 3.0), (440.0, 12.0), (519.0, -2.0), (600.0, 9.0), (640.0, 1.0), (700.0, 4.0)]


def test_frenet_to_cartesian_is_the_circles_point(us101):
    s, d = (jnp.asarray([p[i] for p in POINTS], jnp.float64) for i in (0, 1))
    x, y, theta = jax.jit(scene.frenet_to_cartesian)(us101, s, d)
    want = np.array([_point(*p) for p in POINTS])
    np.testing.assert_allclose(np.asarray(x), want[:, 0], atol=1e-9)
    np.testing.assert_allclose(np.asarray(y), want[:, 1], atol=1e-9)
    np.testing.assert_allclose(np.asarray(theta), want[:, 2], atol=1e-12)
    np.testing.assert_allclose(np.asarray(scene.road_angle_rad(us101, s)), want[:, 2], atol=1e-12)


def test_cartesian_to_frenet_finds_the_foot_of_the_perpendicular_in_any_batch_shape(us101):
    xy = np.array([_point(*p)[:2] for p in POINTS]).reshape(2, 7, 2)
    s, d = jax.jit(scene.cartesian_to_frenet)(us101, jnp.asarray(xy[..., 0]), jnp.asarray(xy[..., 1]))
    assert s.shape == d.shape == (2, 7)
    np.testing.assert_allclose(np.asarray(s), np.reshape([p[0] for p in POINTS], (2, 7)), atol=1e-8)
    np.testing.assert_allclose(np.asarray(d), np.reshape([p[1] for p in POINTS], (2, 7)), atol=1e-8)


def test_a_road_that_starts_at_a_heading():
    cfg = scene.RoadConfig(name="r", lane_width_m=3.5, num_lanes=2, start_heading_deg=30.0,
                     segments=tuple(scene.SegmentConfig(length, None if k == 0.0 else 1.0 / k) for length, k in PIECES))
    road = scene.make_road(cfg)
    heading = math.radians(30.0)
    for s, d in ((50.0, 1.0), (250.0, -2.0), (450.0, 6.0)):
        x, y, th = scene.frenet_to_cartesian(road, jnp.asarray(s), jnp.asarray(d))
        np.testing.assert_allclose([float(x), float(y), float(th)], _point(s, d, heading), atol=1e-9)


def test_curvature_steps_at_the_joints(us101):
    s = jnp.asarray([-5.0, 119.999, 120.0, 279.999, 280.0, 360.0, 519.999, 520.0, 640.0, 900.0])
    np.testing.assert_array_equal(np.asarray(scene.curvature_1pm(us101, s)),
                                  [0.0, 0.0, 1 / 1200, 1 / 1200, 0.0, -1 / 1500, -1 / 1500, 0.0, 0.0, 0.0])
    # integer arc lengths are taken as floats
    angle = scene.road_angle_rad(us101, jnp.asarray([200, 700]))
    assert jnp.issubdtype(angle.dtype, jnp.floating)
    np.testing.assert_allclose(np.asarray(angle), [80 / 1200, 160 / 1200 - 160 / 1500], atol=1e-12)


def test_lane_centres_and_boundaries(us101):
    np.testing.assert_allclose(np.asarray(scene.lane_centre_d_m(us101, jnp.arange(6))),
                               [1.83, 5.49, 9.15, 12.81, 16.47, 20.13], atol=1e-12)
    # either side of a boundary (on it, XLA's division may round either way); off the road, the
    # nearest lane
    d = jnp.asarray([-0.5, 0.0, 3.66 - 1e-9, 3.66 + 1e-9, 7.32 + 1e-9, 18.3 - 1e-9, 18.3 + 1e-9, 21.96, 40.0])
    lanes = scene.lane_index(us101, d)
    assert lanes.dtype == jnp.int32
    np.testing.assert_array_equal(np.asarray(lanes), [0, 0, 0, 1, 2, 4, 5, 5, 5])


@pytest.mark.parametrize("make, ok", [
    (dict(lane_width_m=2.0), True), (dict(lane_width_m=6.0), True),
    (dict(lane_width_m=1.99), False), (dict(lane_width_m=6.01), False),
    (dict(num_lanes=1, auxiliary_lanes=0), True), (dict(num_lanes=12), True),
    (dict(num_lanes=0, auxiliary_lanes=0), False), (dict(num_lanes=13), False),
    (dict(auxiliary_lanes=2), True), (dict(auxiliary_lanes=3), False), (dict(auxiliary_lanes=-1), False),
    (dict(segments=((10.0, None),) * 7), True), (dict(segments=((10.0, None),) * 8), False),
    *[(dict(segments=((10.0, r),)), True) for r in (50.0, -50.0, 1e6)], (dict(segments=((0.5, None),)), True),
    *[(dict(segments=((length, r),)), False) for length, r in ((0.0, None), (-1.0, None), (10.0, 49.99),
                                                                (10.0, -49.99), (10.0, 0.0))],
])
def test_road_limits_are_inclusive_where_documented(make, ok):
    def build():
        fields = dict(name="r", lane_width_m=3.5, num_lanes=3, segments=((100.0, None),)) | make
        return scene.RoadConfig(**fields | {"segments": tuple(scene.SegmentConfig(*s) for s in fields["segments"])})

    if ok:
        build()
    else:
        with pytest.raises(InputError):
            build()


def _road(pieces, lane_width_m=3.5, num_lanes=3):
    segments = tuple(scene.SegmentConfig(length, None if k == 0.0 else 1.0 / k) for length, k in pieces)
    return scene.make_road(scene.RoadConfig(name="r", lane_width_m=lane_width_m, num_lanes=num_lanes, segments=segments))


def test_float32_stays_float32_and_a_joint_between_float32_numbers():
    # A joint at 120.1 m, which float32 cannot hold: a float32 s of 120.1 is the road's joint as
    # float32 sees it, so it takes the bend's curvature (the piece starting at or before s).
    road = _road([(120.1, 0.0), (100.0, 1.0 / 1000.0)])
    kappa = scene.curvature_1pm(road, jnp.asarray([120.1, 120.0], jnp.float32))
    np.testing.assert_array_equal(np.asarray(kappa), np.asarray([1.0 / 1000.0, 0.0], np.float32))
    us101 = scene.load_road("us101")
    x, y, _ = scene.frenet_to_cartesian(us101, jnp.asarray([200.0, 440.0], jnp.float32), jnp.asarray([5.0, 12.0], jnp.float32))
    assert x.dtype == y.dtype == jnp.float32
    want = np.array([_point(200.0, 5.0), _point(440.0, 12.0)])
    np.testing.assert_allclose(np.asarray(x), want[:, 0], atol=2e-4)
    np.testing.assert_allclose(np.asarray(y), want[:, 1], atol=2e-4)
    xy = want[:, :2].astype(np.float32)
    s, d = scene.cartesian_to_frenet(us101, jnp.asarray(xy[:, 0]), jnp.asarray(xy[:, 1]))
    assert s.dtype == d.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(s), [200.0, 440.0], atol=2e-3)
    # y takes x's type (and d takes s's): a float64 one beside a float32 one gives float32
    s, d = scene.cartesian_to_frenet(us101, jnp.asarray(xy[:, 0]), np.asarray(xy[:, 1], np.float64))
    assert s.dtype == d.dtype == jnp.float32
    x, y, th = scene.frenet_to_cartesian(us101, s, np.asarray([5.0, 12.0], np.float64))
    assert x.dtype == y.dtype == th.dtype == jnp.float32


def test_beyond_the_last_segment_the_road_runs_straight():
    # seven segments leave one zero-length pad; the last segment bends, the road beyond it does not
    road = _road([(50.0, 0.0)] * 6 + [(100.0, 1.0 / 500.0)])
    end_heading = 100.0 / 500.0
    s = jnp.asarray([399.0, 401.0, 500.0])  # the bend ends at 400 m
    np.testing.assert_allclose(np.asarray(scene.curvature_1pm(road, s)), [1.0 / 500.0, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(np.asarray(scene.road_angle_rad(road, s))[1:], end_heading, atol=1e-12)
    x, y, _ = scene.frenet_to_cartesian(road, s[1:], jnp.zeros(2))
    assert float(jnp.hypot(x[1] - x[0], y[1] - y[0])) == pytest.approx(99.0, abs=1e-9)
    # and points off it, beyond the end, project onto the straight, not onto the bend's circle
    x, y, th = scene.frenet_to_cartesian(road, s[1:], jnp.asarray([3.0, -4.0]))
    back_s, back_d = scene.cartesian_to_frenet(road, x, y)
    np.testing.assert_allclose(np.asarray(back_s), [401.0, 500.0], atol=1e-9)
    np.testing.assert_allclose(np.asarray(back_d), [3.0, -4.0], atol=1e-9)


def test_projection_converges_far_off_the_road_on_a_bend(us101):
    # Newton's method to float64 round-off in its 4 steps, 40-60 m off the road on either bend
    # (|d| kappa up to 0.05): a step with the wrong derivative converges too, but only linearly.
    pts = [(279.0, 60.0), (279.0, -40.0), (200.0, -60.0), (519.0, 60.0), (440.0, -50.0)]
    xy = np.array([_point(*p)[:2] for p in pts])
    s, d = scene.cartesian_to_frenet(us101, jnp.asarray(xy[:, 0]), jnp.asarray(xy[:, 1]))
    np.testing.assert_allclose(np.asarray(s), [p[0] for p in pts], atol=1e-9)
    np.testing.assert_allclose(np.asarray(d), [p[1] for p in pts], atol=1e-9)


def test_projection_is_the_nearest_point_of_a_sharp_bend():
    # A 90-deg bend of the tightest radius allowed (50 m) between two straights, and points up to
    # 15 m either side of it, near the joints and inside the bend where the straights' extended
    # feet compete with the arc's: each point's (s, d) against the nearest of 1 mm samples of the
    # centreline, drawn from the circle (signed d: left of the direction of travel).
    radius = 50.0
    pieces = [(100.0, 0.0), (0.5 * math.pi * radius, 1.0 / radius), (100.0, 0.0)]
    road = _road(pieces)
    edges = np.cumsum([0.0] + [p[0] for p in pieces])
    s_line = np.arange(-20.0, edges[-1] + 20.0, 1e-3)
    centre = np.array([100.0, radius])
    th = np.clip((s_line - 100.0) / radius, 0.0, 0.5 * math.pi)
    on_arc = centre + radius * np.stack([np.sin(th), -np.cos(th)], -1)
    line = np.where((s_line < 100.0)[:, None], np.stack([s_line, 0 * s_line], -1),
                    np.where((s_line > edges[2])[:, None], np.stack([150.0 + 0 * s_line, 50.0 + s_line - edges[2]], -1),
                             on_arc))
    tangent = np.stack([np.cos(th), np.sin(th)], -1)
    rng = np.random.default_rng(3)
    pts = np.stack([rng.uniform(80.0, 175.0, 60), rng.uniform(-15.0, 70.0, 60)], -1)
    foot = np.array([np.argmin(((p - line) ** 2).sum(-1)) for p in pts])
    rel = pts - line[foot]
    d_want = tangent[foot, 0] * rel[:, 1] - tangent[foot, 1] * rel[:, 0]
    keep = np.abs(d_want) <= 15.0  # within the documented accuracy (|d| well below the radius)
    s, d = scene.cartesian_to_frenet(road, jnp.asarray(pts[keep, 0]), jnp.asarray(pts[keep, 1]))
    assert keep.sum() >= 20
    np.testing.assert_allclose(np.asarray(s), s_line[foot][keep], atol=1e-3)
    np.testing.assert_allclose(np.asarray(d), d_want[keep], atol=1e-5)


def test_shipped_roads_by_name_and_a_bad_road_file(tmp_path):
    assert scene.list_roads() == ["straight", "us101"]
    with pytest.raises(InputError, match="'autobahn'") as err:
        scene.load_road("autobahn")
    assert "straight, us101" in str(err.value)  # the known ones
    assert np.all(np.asarray(scene.road_angle_rad(scene.load_road("straight"), jnp.linspace(0.0, 1000.0, 11))) == 0.0)
    head = 'name = "r"\nlane_width_m = 3.66\nnum_lanes = 3\n'
    for text, culprit in ((head + "lanes = 2\n[[segments]]\nlength_m = 10.0\n", "'lanes'"),
                          (head.replace("3.66", '"wide"') + "[[segments]]\nlength_m = 10.0\n", "lane_width_m"),
                          (head + "[[segments]]\nlength_m = 10.0\nradius_m = 5.0\n", "radius_m"),
                          (head + "segments = []\n", "segments")):
        path = tmp_path / "road.toml"
        path.write_text(text)
        with pytest.raises(InputError, match=culprit):
            scene.load_road(path)


def test_projection_reaches_round_off_on_a_sharp_bend_at_any_heading():
    # Newton's first guess is the point's distance along the piece's start tangent; on a 50 m
    # radius bend entered at 80 deg, 4 steps still reach float64 round-off from it.
    road = scene.make_road(scene.RoadConfig(name="r", lane_width_m=3.5, num_lanes=3, start_heading_deg=80.0,
                                segments=(scene.SegmentConfig(20.0), scene.SegmentConfig(75.0, 50.0), scene.SegmentConfig(50.0))))
    s = jnp.linspace(21.0, 94.0, 30)
    d = jnp.tile(jnp.asarray([-10.0, -4.0, 4.0, 10.0, 0.0]), 6)
    x, y, _ = scene.frenet_to_cartesian(road, s, d)
    back_s, back_d = scene.cartesian_to_frenet(road, x, y)
    np.testing.assert_allclose(np.asarray(back_s), np.asarray(s), atol=1e-9)
    np.testing.assert_allclose(np.asarray(back_d), np.asarray(d), atol=1e-9)


@pytest.fixture(scope="module", params=("us101", "straight"))
def road(request):
    return scene.load_road(request.param)


def test_road_angle_is_the_centreline_derivative(road):
    s = jnp.linspace(-20.0, road.length_m + 20.0, 777, dtype=jnp.float64)
    tangent = jax.jit(jax.vmap(jax.jacfwd(lambda q: jnp.stack(scene.centreline_xy(road, q)))))(s)  # [S, 2]
    assert np.allclose(jnp.linalg.norm(tangent, axis=-1), 1.0, atol=1e-12)  # s is arc length
    angle = jax.jit(scene.road_angle_rad)(road, s)
    assert np.allclose(jnp.arctan2(tangent[:, 1], tangent[:, 0]), angle, atol=1e-12)
    h = 1e-4  # and by finite differences, independent of autodiff
    xp, yp = scene.centreline_xy(road, s + h)
    xm, ym = scene.centreline_xy(road, s - h)
    assert np.allclose(jnp.arctan2(yp - ym, xp - xm), angle, atol=1e-6)
    # ... and the curvature is the road angle's derivative (away from the pieces' joints).
    kappa = jax.jit(scene.curvature_1pm)(road, s)
    fd = (scene.road_angle_rad(road, s + h) - scene.road_angle_rad(road, s - h)) / (2 * h)
    joint = np.min(np.abs(np.asarray(s)[:, None] - np.asarray(road.start_s_m)[None, :]), axis=1) < 2 * h
    assert np.allclose(kappa[~joint], fd[~joint], atol=1e-9)


def test_gradients_match_finite_differences():
    road = scene.load_road("us101")
    # Points on a bend, on a straight piece and near a joint; d left and right of the lanes.
    pts = jnp.array([[200.0, 5.0], [60.0, 12.0], [280.3, 20.0], [450.0, -1.0]], jnp.float64)

    def both(p):
        x, y, th = scene.frenet_to_cartesian(road, p[0], p[1])
        s, d = scene.cartesian_to_frenet(road, x + 0.3, y - 0.2)
        return jnp.stack([x, y, th, s, d])

    jvp = jax.jit(jax.vmap(lambda p, t: jax.jvp(both, (p,), (t,)), in_axes=(0, None)))  # compiled once
    jac = jnp.stack([jvp(pts, e)[1] for e in jnp.eye(2)], axis=-1)  # [P, 5, 2]
    h = 1e-5
    fd = jnp.stack([(jvp(pts + h * e, e)[0] - jvp(pts - h * e, e)[0]) / (2 * h) for e in jnp.eye(2)], axis=-1)
    assert np.all(np.isfinite(jac))
    assert np.allclose(jac, fd, atol=1e-6), (jac, fd)
