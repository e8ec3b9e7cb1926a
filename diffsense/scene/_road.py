"""Road geometry: a reference line of straight and circular pieces, lanes, Frenet <-> Cartesian.

The reference line is the road's right edge (the right boundary of lane 0, the rightmost lane);
d is the lateral offset to the left of it, so the lane k centre is at d = (k + 1/2) w and the
road covers 0 <= d <= num_lanes * w. Pieces have constant curvature kappa (0 for straight), so
the centreline has a closed form: a chord of length sigma * sinc(kappa sigma / 2) in the
direction theta0 + kappa sigma / 2. `jnp.sinc` has a well-defined derivative at 0, so one formula
serves straight and curved pieces and stays differentiable. Before s = 0 the first piece continues;
beyond the end the road continues straight. Every road is padded to MAX_PIECES pieces (zero-length
straight ones at the end) and carries its sizes as arrays, so one compiled simulation serves all.

Units: s, d, x, y [m]; angles [rad]; curvature [1/m].
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from diffsense.config import list_defaults
from diffsense.runtime import InputError
from diffsense.scene._named_config import load_named

# Newton steps of the projection onto a piece: the error squares each step (|d| kappa << 1 on a
# highway), so 4 steps from the tangent-line guess reach float64 round-off.
_PROJECTION_STEPS = 4
MAX_PIECES = 8


@dataclasses.dataclass(frozen=True)
class SegmentConfig:
    """One piece of the reference line.

    Attributes:
        length_m: arc length of the piece [m].
        radius_m: turn radius [m]; positive bends left, negative right; omitted = straight.
    """

    length_m: float
    radius_m: float | None = None

    def __post_init__(self):
        if not self.length_m > 0.0:
            raise InputError(f"segment length_m must be > 0, got {self.length_m}")
        if self.radius_m is not None and abs(self.radius_m) < 50.0:
            raise InputError(f"segment radius_m must be None or |radius| >= 50 m, got {self.radius_m}")


@dataclasses.dataclass(frozen=True)
class RoadConfig:
    """A road as written in configs/roads/*.toml.

    Attributes:
        name: short name used by scenarios (`road = "us101"`).
        description: what the road represents and where its numbers come from.
        lane_width_m: width of every lane [m].
        num_lanes: lane count; lane 0 is the rightmost.
        auxiliary_lanes: how many of the rightmost lanes are auxiliary (merge/exit) lanes [-].
        start_heading_deg: world yaw of the reference line at s = 0 [deg].
        segments: the pieces, in driving order.
    """

    name: str
    lane_width_m: float
    num_lanes: int
    segments: tuple[SegmentConfig, ...]
    description: str = ""
    auxiliary_lanes: int = 0
    start_heading_deg: float = 0.0

    def __post_init__(self):
        if not 2.0 <= self.lane_width_m <= 6.0:
            raise InputError(f"lane_width_m must be in [2, 6] m, got {self.lane_width_m}")
        if not 1 <= self.num_lanes <= 12:
            raise InputError(f"num_lanes must be in [1, 12], got {self.num_lanes}")
        if not 0 <= self.auxiliary_lanes < self.num_lanes:
            raise InputError(f"auxiliary_lanes must be in [0, num_lanes), got {self.auxiliary_lanes}")
        if not 1 <= len(self.segments) <= MAX_PIECES - 1:
            raise InputError(f"a road needs 1 to {MAX_PIECES - 1} segments, got {len(self.segments)}")


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Road:
    """The reference line as K = MAX_PIECES constant-curvature pieces, ready for JAX.

    Every field is an array (no static metadata), so roads of any shape share compilations.

    Attributes:
        start_s_m: [K] arc length where each piece starts [m] (start_s_m[0] = 0).
        curvature_1pm: [K] signed curvature of each piece, left positive [1/m].
        start_x_m: [K] world x of each piece's start [m].
        start_y_m: [K] world y of each piece's start [m].
        start_heading_rad: [K] world yaw of the reference line at each piece's start [rad].
        length_m: [] total arc length [m].
        lane_width_m: [] [m].
        num_lanes: [] lane count.
        auxiliary_lanes: [] how many of the rightmost lanes are auxiliary.
    """

    start_s_m: Float[Array, " K"]
    curvature_1pm: Float[Array, " K"]
    start_x_m: Float[Array, " K"]
    start_y_m: Float[Array, " K"]
    start_heading_rad: Float[Array, " K"]
    length_m: Float[Array, ""]
    lane_width_m: Float[Array, ""]
    num_lanes: Int[Array, ""]
    auxiliary_lanes: Int[Array, ""]

    @property
    def width_m(self) -> float:
        return self.num_lanes * self.lane_width_m


def make_road(cfg: RoadConfig) -> Road:
    """Chain the pieces of `cfg` into a `Road` (piece starts integrated in float64 numpy)."""
    pad = MAX_PIECES - len(cfg.segments)  # zero-length straight pieces: the straight run-out
    lengths = np.array([seg.length_m for seg in cfg.segments] + [0.0] * pad, dtype=np.float64)
    kappa = np.array([0.0 if seg.radius_m is None else 1.0 / seg.radius_m for seg in cfg.segments] + [0.0] * pad)
    s0, x0, y0, th0 = [0.0], [0.0], [0.0], [math.radians(cfg.start_heading_deg)]
    for length, k in zip(lengths[:-1], kappa[:-1]):
        mid = th0[-1] + 0.5 * k * length
        chord = length * np.sinc(0.5 * k * length / np.pi)
        s0.append(s0[-1] + length)
        x0.append(x0[-1] + chord * math.cos(mid))
        y0.append(y0[-1] + chord * math.sin(mid))
        th0.append(th0[-1] + k * length)
    return Road(
        start_s_m=np.array(s0), curvature_1pm=kappa, start_x_m=np.array(x0),
        start_y_m=np.array(y0), start_heading_rad=np.array(th0),
        length_m=np.float64(lengths.sum()), lane_width_m=np.float64(cfg.lane_width_m),
        num_lanes=np.int32(cfg.num_lanes), auxiliary_lanes=np.int32(cfg.auxiliary_lanes),
    )


def list_roads() -> list[str]:
    """Names of the shipped roads (configs/roads/*.toml)."""
    return list_defaults("roads")


def load_road_config(name_or_path: str | Path) -> RoadConfig:
    """A shipped road by name (`"us101"`, `"straight"`) or a TOML file by path."""
    return load_named(RoadConfig, "roads", name_or_path, "road")


def load_road(name_or_path: str | Path) -> Road:
    """`make_road(load_road_config(name_or_path))`."""
    return make_road(load_road_config(name_or_path))


def _pieces(road: Road, s: Array):
    """Per-point piece parameters (start s, curvature, start pose), cast to the dtype of s."""
    # Ties (zero-length pads) resolve to the last piece starting at or before s.
    idx = jnp.clip(jnp.searchsorted(jnp.asarray(road.start_s_m, s.dtype), s, side="right") - 1,
                   0, road.start_s_m.shape[0] - 1)
    take = lambda a: jnp.asarray(a, s.dtype)[idx]  # noqa: E731
    return (take(road.start_s_m), take(road.curvature_1pm), take(road.start_x_m),
            take(road.start_y_m), take(road.start_heading_rad))


def _piece_point(sigma, kappa, x0, y0, th0):
    """Centreline point and yaw at arc length sigma along one piece (closed form)."""
    half_turn = 0.5 * kappa * sigma
    chord = sigma * jnp.sinc(half_turn / jnp.pi)
    mid = th0 + half_turn
    return x0 + chord * jnp.cos(mid), y0 + chord * jnp.sin(mid), th0 + kappa * sigma


def _float(a: ArrayLike) -> Array:
    a = jnp.asarray(a)
    return a if jnp.issubdtype(a.dtype, jnp.floating) else a.astype(jnp.result_type(float))


def road_angle_rad(road: Road, s_m: Float[ArrayLike, "*S"]) -> Float[Array, "*S"]:
    """World yaw of the reference line at arc length s [rad]."""
    s = _float(s_m)
    start, kappa, _, _, th0 = _pieces(road, s)
    return th0 + kappa * (s - start)


def curvature_1pm(road: Road, s_m: Float[ArrayLike, "*S"]) -> Float[Array, "*S"]:
    """Signed curvature of the reference line at s, left positive [1/m]."""
    s = _float(s_m)
    return _pieces(road, s)[1]


def centreline_xy(road: Road, s_m: Float[ArrayLike, "*S"]) -> tuple[Float[Array, "*S"], Float[Array, "*S"]]:
    """World (x, y) of the reference line (d = 0) at s [m]."""
    x, y, _ = frenet_to_cartesian(road, s_m, jnp.zeros_like(_float(s_m)))
    return x, y


def frenet_to_cartesian(
    road: Road, s_m: Float[ArrayLike, "*S"], d_m: Float[ArrayLike, "*S"]
) -> tuple[Float[Array, "*S"], Float[Array, "*S"], Float[Array, "*S"]]:
    """World (x [m], y [m], road angle [rad]) of the road-frame point (s, d)."""
    s = _float(s_m)
    d = jnp.asarray(d_m, s.dtype)
    start, kappa, x0, y0, th0 = _pieces(road, s)
    x, y, theta = _piece_point(s - start, kappa, x0, y0, th0)
    return x - d * jnp.sin(theta), y + d * jnp.cos(theta), theta


def cartesian_to_frenet(
    road: Road, x_m: Float[ArrayLike, "*S"], y_m: Float[ArrayLike, "*S"]
) -> tuple[Float[Array, "*S"], Float[Array, "*S"]]:
    """Road-frame (s, d) [m] of the world point (x, y): the foot of the perpendicular.

    Each piece is searched by Newton's method on (p - c(sigma)) . t(sigma) = 0 and the nearest
    foot wins; interior pieces are clipped to their extent, the first and last pieces extend.
    Accurate while |d| is well below the smallest radius (always, on a highway).
    """
    x = _float(x_m)
    y = jnp.asarray(y_m, x.dtype)
    cast = lambda a: jnp.asarray(a, x.dtype)  # noqa: E731
    start, kappa = cast(road.start_s_m), cast(road.curvature_1pm)
    x0, y0, th0 = cast(road.start_x_m), cast(road.start_y_m), cast(road.start_heading_rad)
    num = start.shape[0]
    ends = jnp.concatenate([start[1:], cast(road.length_m)[None]]) - start
    lo = jnp.where(jnp.arange(num) == 0, -jnp.inf, 0.0)
    hi = jnp.where(jnp.arange(num) == num - 1, jnp.inf, ends)
    px, py = x[..., None], y[..., None]  # broadcast against the K pieces

    def offsets(sigma):
        cx, cy, theta = _piece_point(sigma, kappa, x0, y0, th0)
        ex, ey = px - cx, py - cy
        tx, ty = jnp.cos(theta), jnp.sin(theta)
        return ex * tx + ey * ty, -ex * ty + ey * tx  # along, left

    sigma = (px - x0) * jnp.cos(th0) + (py - y0) * jnp.sin(th0)
    for _ in range(_PROJECTION_STEPS):
        along, left = offsets(sigma)
        # d/dsigma of along = -(1 - kappa * left), positive unless the point is near the centre of
        # curvature (hundreds of metres off the road); the floor keeps a far piece's step finite.
        sigma = jnp.clip(sigma + along / jnp.maximum(1.0 - kappa * left, 0.1), lo, hi)
    along, left = offsets(sigma)
    best = jnp.argmin(along**2 + left**2, axis=-1)
    pick = lambda a: jnp.take_along_axis(jnp.broadcast_to(a, sigma.shape), best[..., None], -1)[..., 0]  # noqa: E731
    return pick(start + sigma), pick(left)


def lane_centre_d_m(road: Road, lane: Int[ArrayLike, "*S"]) -> Float[Array, "*S"]:
    """Lateral offset of lane `lane`'s centre (lane 0 = rightmost) [m]."""
    return (jnp.asarray(lane) + 0.5) * jnp.asarray(road.lane_width_m)


def lane_index(road: Road, d_m: Float[ArrayLike, "*S"]) -> Int[Array, "*S"]:
    """Index of the lane containing lateral offset d (clipped to the road's lanes) [-]."""
    d = jnp.asarray(d_m)
    lane = jnp.floor(d / jnp.asarray(road.lane_width_m, d.dtype)).astype(jnp.int32)
    return jnp.clip(lane, 0, road.num_lanes - 1)
