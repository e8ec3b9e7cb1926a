"""A sensor suite: several sensors on one ego, fused into one track per vehicle.

    suite = Suite((Radar.from_toml(), Camera.from_toml()))      # names "radar", "camera"
    det = suite.detect(scene, {"radar.hfov_deg": 60.0, "camera.width_px": 1920.0}, key)

Detection. A vehicle's fused track exists when at least one member detects it. The members'
detections are taken as independent given the scene (each has its own gates and its own noise
draws; shared causes such as occlusion by the same vehicle are already inside each member's
probability), so the fused probability is p = 1 - prod_i (1 - p_i), formed as
-expm1(sum_i log1p(-p_i)). In hard mode this is the OR of the 0/1 detections.

Position. When the members in a set S detect, their measurements are fused by inverse
(co)variance weighting: x_S = (sum_{i in S} C_i^-1)^-1 sum_{i in S} C_i^-1 x_i, with C_i the
member's world covariance (`_member.py`). The fused measurement is the expectation of x_S over
which set detects, given that the track exists: weights pi_S proportional to
prod_{i in S} p_i prod_{j not in S} (1 - p_j), normalised over the non-empty sets in log space.
So a member with p = 0 contributes nothing (its sets have weight 0), with every p in {0, 1}
(hard mode) it is exactly inverse-variance fusion of the detecting members, and the fused
covariance `Covariance` is the same expectation of C_S = (sum_{i in S} C_i^-1)^-1, which is
below every detecting member's (in the positive semi-definite order). A draw of the detections
(the reference objective's) decides each member on its own: `member_views` gives the members'
views, `fuse_members` fuses them with the drawn 0/1 in place of each p. A suite of M members
forms 2^M - 1 sets; M <= 6.

Parameters are the members' under qualified names, "<member>.<parameter>" ("radar.hfov_deg",
"corner_left.yaw_deg"). A member's `Mounting` gives its mounting parameters their defaults and
domain (its envelope, inside the global one of `_mount.py`): two radars of one kind sit apart.
Noise: member i draws from the i-th key of `jax.random.split(key, M)` (or is given draws
[M, 2, T, V]), so members' noises are independent, and a member's draws in a suite differ from
the same sensor's alone with the same key.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Sequence
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from diffsense.runtime import InputError
from diffsense.scene import EGO_INDEX, Scene
from diffsense.sensors._datatypes import Detections
from diffsense.sensors._gates import Mode
from diffsense.sensors._measure import KeyOrNoise
from diffsense.sensors._member import Covariance, member_view
from diffsense.sensors._mount import MOUNT_NAMES, Mounting
from diffsense.sensors._params import ParamSpec
from diffsense.sensors._sensor import Sensor
from diffsense.sensors._weather import CLEAR, Weather

MAX_MEMBERS = 6
# log p of p = 0 (and log(1 - p) of p = 1): exp() of it is 0 in any float type, and differences
# of such numbers stay finite in the normalisation (no inf - inf).
_LOG_ZERO = -1e4


def _safe_log(x: Array) -> Array:
    """log(x) for x in [0, 1], _LOG_ZERO at 0, with a zero (not NaN) gradient there."""
    ok = x > 0
    return jnp.where(ok, jnp.log(jnp.where(ok, x, 1.0)), _LOG_ZERO)


def _information(c: Covariance) -> Covariance:
    """C^-1 of a 2x2 covariance (positive definite: each member's variances are floored)."""
    det = c.det()
    return Covariance(xx=c.yy / det, xy=-c.xy / det, yy=c.xx / det)


def _subsets(m: int) -> list[tuple[int, ...]]:
    return [s for k in range(1, m + 1) for s in itertools.combinations(range(m), k)]


def fuse(dets: Sequence[Detections], covs: Sequence[Covariance]) -> tuple[Detections, Covariance]:
    """Fused Detections and covariance of independent members (module docstring); arrays [..., T, V]."""
    log_p = [_safe_log(d.p_detect) for d in dets]
    log_q = [_safe_log(1.0 - d.p_detect) for d in dets]
    p = -jnp.expm1(sum(log_q))
    info = [_information(c) for c in covs]
    logits, xs, ys, cs = [], [], [], []
    for s in _subsets(len(dets)):
        logits.append(sum(log_p[i] if i in s else log_q[i] for i in range(len(dets))))
        j = Covariance(*(sum(getattr(info[i], f) for i in s) for f in ("xx", "xy", "yy")))
        c = _information(j)  # C_S = J^-1
        bx = sum(info[i].xx * dets[i].x_m + info[i].xy * dets[i].y_m for i in s)
        by = sum(info[i].xy * dets[i].x_m + info[i].yy * dets[i].y_m for i in s)
        xs.append(c.xx * bx + c.xy * by)
        ys.append(c.xy * bx + c.yy * by)
        cs.append(c)
    w = jax.nn.softmax(jnp.stack(logits), axis=0)  # pi_S given that the track exists

    def expect(values):
        return jnp.sum(w * jnp.stack(values), axis=0)

    fused = Covariance(*(expect([getattr(c, f) for c in cs]) for f in ("xx", "xy", "yy")))
    return Detections(p_detect=p, x_m=expect(xs), y_m=expect(ys)), fused


def fuse_members(scene: Scene, views: Sequence[tuple[Detections, Covariance]],
                 p_detect: Sequence[Array] | None = None) -> tuple[Detections, Covariance]:
    """The fused Detections and covariance of the members' `views` (`Suite.member_views`) of
    `scene`, arrays [..., T, V]; `p_detect` replaces each member's probability when given (a draw:
    with every p in {0, 1} the fused position is the inverse-variance fusion of the members that
    drew a detection)."""
    dets = [v[0] for v in views]
    if p_detect is not None:
        dets = [dataclasses.replace(d, p_detect=p) for d, p in zip(dets, p_detect, strict=True)]
    det, cov = fuse(dets, [v[1] for v in views])
    # The ego knows itself and padding stays where the scene put it: the members agree on
    # those positions, and fusion would reproduce them only to rounding.
    known = (jnp.arange(scene.x_m.shape[-1]) == EGO_INDEX) | ~(scene.present[..., None, :] != 0)  # [..., T, V]
    det = Detections(p_detect=det.p_detect, x_m=jnp.where(known, scene.x_m, det.x_m),
                     y_m=jnp.where(known, scene.y_m, det.y_m))
    return det, cov


def _member_names(members: tuple[Sensor, ...], names: Sequence[str] | None) -> tuple[str, ...]:
    """The members' names: each one's kind by default; non-empty, without '.', each once."""
    names = tuple(m.kind for m in members) if names is None else tuple(str(n) for n in names)
    if len(names) != len(members):
        raise InputError(f"{len(names)} names for {len(members)} sensors")
    for n in names:
        if not n or "." in n:
            raise InputError(f"a suite member's name is non-empty and has no '.', got {n!r}")
    if len(set(names)) != len(names):
        twice = min(n for n in set(names) if names.count(n) > 1)
        raise InputError(f"suite member named twice: {twice} (give names=...)")
    return names


def _check_mounting(name: str, member: Sensor, mounting: Mounting) -> None:
    """Refuse a mounting the member has no parameter for, or a default outside its envelope."""
    own = {s.name: s for s in member.param_specs()}
    missing = sorted(mounting.names() - set(own))
    if missing:
        raise InputError(f"member {name}: its sensor has no mounting parameter {missing[0]}")
    for m in MOUNT_NAMES:
        if m not in own:
            continue
        lo, hi = mounting.domain(m)
        value = mounting.default(m, own[m].default)
        if not lo <= value <= hi:
            raise InputError(f"member {name}: its {m} default {value:g} is outside its envelope [{lo:g}, {hi:g}] "
                             f"{own[m].unit}")


def _qualified(name: str, spec: ParamSpec, mounting: Mounting) -> ParamSpec:
    """A member's parameter under its qualified name; a mounting one with the member's default
    and envelope as its domain."""
    spec = dataclasses.replace(spec, name=f"{name}.{spec.name}", doc=f"{name}: {spec.doc}")
    base = spec.name.split(".", 1)[1]
    if base not in MOUNT_NAMES or base not in mounting.names():
        return spec
    lo, hi = mounting.domain(base)
    return dataclasses.replace(spec, lower=lo, upper=hi, lower_open=False, default=mounting.default(base, spec.default))


class Suite(Sensor):
    """Sensors on one ego fused into one track per vehicle (module docstring for the rules).

    `members` are the sensors; `names` their prefixes in qualified parameter names (default:
    each member's `kind`; give names when two members are of one kind); `mountings` each
    member's mounting defaults and envelope (`Mounting`; default: the sensor's own defaults
    and the global envelope), which become the defaults and domains of its mounting parameters.
    """

    members: tuple[Sensor, ...]
    names: tuple[str, ...] = eqx.field(static=True)
    mountings: tuple[Mounting, ...] = eqx.field(static=True)
    kind: ClassVar[str] = "suite"

    def __init__(self, members: Sequence[Sensor], names: Sequence[str] | None = None,
                 mountings: Sequence[Mounting | None] | None = None):
        members = tuple(members)
        if not 1 <= len(members) <= MAX_MEMBERS:
            raise InputError(f"a suite has 1 to {MAX_MEMBERS} sensors, got {len(members)}")
        for m in members:
            if not isinstance(m, Sensor):
                raise InputError(f"a suite's members are Sensors, got {type(m).__name__}")
        self.members, self.names = members, _member_names(members, names)
        mountings = (None,) * len(members) if mountings is None else tuple(mountings)
        if len(mountings) != len(members):
            raise InputError(f"{len(mountings)} mountings for {len(members)} sensors")
        self.mountings = tuple(Mounting() if m is None else m for m in mountings)
        for name, member, mounting in zip(self.names, self.members, self.mountings):
            _check_mounting(name, member, mounting)

    def param_specs(self) -> tuple[ParamSpec, ...]:
        return tuple(_qualified(n, s, mounting) for n, m, mounting in zip(self.names, self.members, self.mountings)
                     for s in m.param_specs())

    @property
    def mount_x_m(self) -> float:
        """The farthest-forward member's mounting [m] (what reaches farthest sets the scene's extent)."""
        return max(mounting.default("mount_x_m", m.mount_x_m) for m, mounting in zip(self.members, self.mountings))

    def _split(self, r: dict[str, Any]) -> list[dict[str, Any]]:
        return [{s.name: r[f"{n}.{s.name}"] for s in m.param_specs()} for n, m in zip(self.names, self.members)]

    def _noises(self, noise: KeyOrNoise, scene: Scene) -> list:
        m = len(self.members)
        if jnp.issubdtype(noise.dtype, jnp.floating):
            expected = (m, 2, *scene.x_m.shape)
            if noise.shape != expected:
                raise InputError(f"suite measurement noise has shape {noise.shape}, expected {expected}")
            return [noise[i] for i in range(m)]
        keys = jax.random.split(noise, m)
        return [keys[i] for i in range(m)]

    def member_views(self, scene: Scene, r: dict[str, Any] | None = None, noise: KeyOrNoise | None = None, *,
                     mode: Mode = "soft", temperature: Float[ArrayLike, ""] = 1.0, weather: Weather = CLEAR
                     ) -> list[tuple[Detections, Covariance]]:
        """Each member's Detections [T, V] of `scene` and their world covariance [m^2], unfused:
        the independent detection events a draw decides one by one (`fuse_members`)."""
        full = self.defaults()
        for name, value in (r or {}).items():
            self.spec(name)
            full[name] = value
        if noise is None:
            raise InputError("detect needs a noise key (or the noise draws)")
        return [member_view(m, scene, ri, ni, mode, temperature, weather)
                for m, ri, ni in zip(self.members, self._split(full), self._noises(noise, scene))]

    def detect_with_covariance(self, scene: Scene, r: dict[str, Any] | None = None,
                               noise: KeyOrNoise | None = None, *, mode: Mode = "soft",
                               temperature: Float[ArrayLike, ""] = 1.0, weather: Weather = CLEAR
                               ) -> tuple[Detections, Covariance]:
        """`detect`, and the fused measurement covariance [T, V] [m^2]; every member sees `weather`."""
        views = self.member_views(scene, r, noise, mode=mode, temperature=temperature, weather=weather)
        return fuse_members(scene, views)

    def _detect(self, scene: Scene, r: dict[str, Any], noise: KeyOrNoise, mode: Mode,
                temperature, weather: Weather = CLEAR) -> Detections:
        return self.detect_with_covariance(scene, r, noise, mode=mode, temperature=temperature, weather=weather)[0]
