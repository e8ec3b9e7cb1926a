"""Training traffic's state: the vehicles of a simulation, their dynamic state, the recording,
and the initial placement on the ring road.

Vehicles i = k * vehicles_per_lane + j start in lane k (0 = rightmost), bumper to bumper with
their IDM standstill gap s0 plus a random share of the free length of the ring, at the IDM
equilibrium speed of their gap. Lateral offsets d are measured from the right road edge, left
positive, so lane k's centre is at d = (k + 1/2) * lane_width.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int, PRNGKeyArray

from diffsense import runtime
from diffsense.scene._idm import IDMParams
from diffsense.scene._lane_change import quintic_progress
from diffsense.scene._traffic_config import TrafficConfig

DT_S = 0.1
# Bisection steps for the initial equilibrium speed: halves [0, v0] to < 1e-5 of v0.
_EQUILIBRIUM_BISECTIONS = 18


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class TrafficVehicles:
    """Fixed properties of the V vehicles of one simulation (leading N for a batch).

    Attributes:
        length_m, width_m: [V] body size [m].
        kind: [V] CAR, VAN or TRUCK.
        idm: IDMParams with [V] fields; its desired speed is the initial one.
        politeness: [V] MOBIL politeness [-].
        max_desired_speed_mps: [V] the kind's cap on desired speed [m/s].
        mean_desired_speed_mps: [] the simulation's mean desired speed [m/s].
        ring_length_m: [] length of the ring road [m].
    """

    length_m: Float[Array, "*N V"]
    width_m: Float[Array, "*N V"]
    kind: Int[Array, "*N V"]
    idm: IDMParams
    politeness: Float[Array, "*N V"]
    max_desired_speed_mps: Float[Array, "*N V"]
    mean_desired_speed_mps: Float[Array, "*N"]
    ring_length_m: Float[Array, "*N"]


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class TrafficState:
    """Dynamic state of one simulation (leading N for a batch).

    Attributes:
        s_m: [V] unwrapped arc length [m].
        speed_mps: [V] longitudinal speed [m/s].
        lane: [V] the lane a vehicle is in, or leaves while changing (0 = rightmost) [-].
        target_lane: [V] the lane it moves to; equal to `lane` when not changing [-].
        since_change_s: [V] time since the last lane change started [s].
        change_duration_s: [V] duration of the current (or last) lane change [s].
        desired_speed_mps: [V] current IDM v0 [m/s].
        preferred_lane: [V] the lane the driver's route asks for (an exit, a merge) [-].
    """

    s_m: Float[Array, "*N V"]
    speed_mps: Float[Array, "*N V"]
    lane: Int[Array, "*N V"]
    target_lane: Int[Array, "*N V"]
    since_change_s: Float[Array, "*N V"]
    change_duration_s: Float[Array, "*N V"]
    desired_speed_mps: Float[Array, "*N V"]
    preferred_lane: Int[Array, "*N V"]


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class TrafficTrajectories:
    """Recorded traffic at 10 Hz: T frames of V vehicles (leading N for a batch).

    Attributes:
        s_m: [T, V] unwrapped arc length [m] (positions on the ring are s mod ring_length_m).
        d_m: [T, V] lateral offset from the right road edge, left positive [m].
        speed_mps: [T, V] longitudinal speed [m/s].
        lane: [T, V] the lane a vehicle is in or leaves while changing [-].
        target_lane: [T, V] the lane it changes to (= lane when not changing) [-].
        vehicles: the fixed vehicle properties.
        dt_s: frame period [s] (static).
    """

    s_m: Float[Array, "*N T V"]
    d_m: Float[Array, "*N T V"]
    speed_mps: Float[Array, "*N T V"]
    lane: Int[Array, "*N T V"]
    target_lane: Int[Array, "*N T V"]
    vehicles: TrafficVehicles
    dt_s: float = dataclasses.field(default=DT_S, metadata=dict(static=True))

    def centre_lane(self, lane_width_m: float) -> Int[Array, "*N T V"]:
        """The lane the vehicle centre is in (what a lane detector reports) [-]."""
        return jnp.floor(self.d_m / lane_width_m).astype(jnp.int32)


def num_steps(cfg: TrafficConfig) -> tuple[int, int]:
    """(warm-up steps, recorded steps) at 10 Hz for one simulation of `cfg`.

    The recording spans 4 s before the first prediction instant (the lateral label looks 4 s
    back), the window of instants, and 5 s after the last one (the future).
    """
    warmup = round(cfg.sampling.warmup_s / DT_S)
    recorded = round((4.0 + cfg.sampling.window_s + 5.0) / DT_S) + 1
    return warmup, recorded


def _uniform(key: PRNGKeyArray, interval, shape, dtype) -> Array:
    lo, hi = interval
    return runtime.uniform(key, shape, dtype, lo, hi)


def _by_kind(kind: Int[Array, "V"], u: Float[Array, "V"], intervals) -> Float[Array, "V"]:
    """Draw per vehicle from its kind's interval, given u ~ U(0, 1)."""
    lo = jnp.asarray([i[0] for i in intervals], u.dtype)[kind]
    hi = jnp.asarray([i[1] for i in intervals], u.dtype)[kind]
    return lo + u * (hi - lo)


def _equilibrium_speed(gap_m: Float[Array, "V"], p: IDMParams) -> Float[Array, "V"]:
    """The IDM speed at which `gap_m` is the steady-state gap, by bisection on [0, v0] [m/s]."""

    def excess_gap(v):  # s0 + vT - gap * sqrt(1 - (v/v0)^delta): increasing in v
        free = jnp.clip(1.0 - (v / p.desired_speed_mps) ** p.accel_exponent, 0.0, 1.0)
        return p.min_gap_m + v * p.time_headway_s - gap_m * jnp.sqrt(free)

    def bisect(_, bounds):
        lo, hi = bounds
        mid = 0.5 * (lo + hi)
        below = excess_gap(mid) < 0.0
        return jnp.where(below, mid, lo), jnp.where(below, hi, mid)

    lo, _ = jax.lax.fori_loop(0, _EQUILIBRIUM_BISECTIONS, bisect, (jnp.zeros_like(gap_m), p.desired_speed_mps))
    return lo


def init_traffic(cfg: TrafficConfig, key: PRNGKeyArray, dtype=jnp.float32) -> tuple[TrafficVehicles, TrafficState]:
    """Draw one simulation: its density and speed level, the vehicles, and an equilibrium start.

    Vehicles i = k * vehicles_per_lane + j start in lane k, spaced with random extra gaps; the
    ring is lengthened if the drawn density cannot hold the drawn vehicles with their IDM gaps.
    """
    road, traffic = cfg.road, cfg.traffic
    n_lanes, per_lane = road.num_lanes, road.vehicles_per_lane
    num_v = cfg.num_vehicles
    keys = jax.random.split(key, 12)
    density = _uniform(keys[0], traffic.density_veh_per_km_lane, (), dtype)
    mean_v0 = _uniform(keys[1], traffic.desired_speed_mps, (), dtype)
    kind = jax.random.choice(keys[2], 3, (num_v,), p=jnp.asarray(traffic.kind_probabilities, dtype)).astype(jnp.int32)
    u = runtime.uniform(keys[3], (7, num_v), dtype)
    kinds = cfg.kinds
    length = _by_kind(kind, u[0], [k.length_m for k in kinds])
    width = _by_kind(kind, u[1], [k.width_m for k in kinds])
    cap = jnp.asarray([k.max_desired_speed_mps for k in kinds], dtype)[kind]
    spread = traffic.desired_speed_spread
    v0 = jnp.minimum(mean_v0 * _uniform(keys[4], (1.0 - spread, 1.0 + spread), (num_v,), dtype), cap)
    idm = IDMParams(
        desired_speed_mps=v0,
        time_headway_s=_by_kind(kind, u[2], [k.time_headway_s for k in kinds]),
        min_gap_m=_by_kind(kind, u[3], [k.min_gap_m for k in kinds]),
        max_accel_mps2=_by_kind(kind, u[4], [k.max_accel_mps2 for k in kinds]),
        comfort_decel_mps2=_by_kind(kind, u[5], [k.comfort_decel_mps2 for k in kinds]),
        accel_exponent=jnp.full((num_v,), traffic.accel_exponent, dtype),
    )
    politeness = _uniform(keys[5], cfg.lane_change.politeness, (num_v,), dtype)

    # Place each lane's vehicles around the ring: body + s0 + a random share of the free length.
    need = (length + idm.min_gap_m).reshape(n_lanes, per_lane)
    ring = jnp.maximum(per_lane * 1000.0 / density, jnp.max(jnp.sum(need, axis=1)) * 1.05)
    weights = runtime.uniform(keys[6], (n_lanes, per_lane), dtype, 0.5, 1.5)
    extra = (ring - jnp.sum(need, axis=1, keepdims=True)) * weights / jnp.sum(weights, axis=1, keepdims=True)
    pitch = need + extra  # from a vehicle's rear to the next one's rear
    lane_offset = runtime.uniform(keys[7], (n_lanes, 1), dtype, 0.0, 1.0) * ring
    rear = lane_offset + jnp.cumsum(pitch, axis=1) - pitch
    s = (rear.reshape(num_v) + 0.5 * length)
    gap = (pitch - need).reshape(num_v) + idm.min_gap_m
    speed = _equilibrium_speed(gap, idm)

    lane = (jnp.arange(num_v) // per_lane).astype(jnp.int32)
    vehicles = TrafficVehicles(
        length_m=length, width_m=width, kind=kind, idm=idm, politeness=politeness,
        max_desired_speed_mps=cap, mean_desired_speed_mps=mean_v0, ring_length_m=ring,
    )
    state = TrafficState(
        s_m=s, speed_mps=speed, lane=lane, target_lane=lane,
        since_change_s=jnp.full((num_v,), 1e3, dtype),  # long ago: free to change at once
        change_duration_s=jnp.full((num_v,), cfg.lane_change.duration_s[0], dtype),
        desired_speed_mps=v0,
        preferred_lane=jax.random.randint(keys[8], (num_v,), 0, n_lanes, dtype=jnp.int32),
    )
    return vehicles, state


def lateral_offset_m(state: TrafficState, lane_width_m: float) -> Float[Array, "V"]:
    """Lateral offset of each vehicle centre from the right road edge [m]."""
    dtype = state.s_m.dtype  # float32 stays float32 under jax_enable_x64 (same data either way)
    d_from = (state.lane.astype(dtype) + 0.5) * lane_width_m
    d_to = (state.target_lane.astype(dtype) + 0.5) * lane_width_m
    progress = quintic_progress(state.since_change_s, 0.0, state.change_duration_s)
    return d_from + (d_to - d_from) * progress
