"""Scenario variants: a config and a PRNG key -> the start state and plan of every vehicle.

Vehicle order: 0 ego, 1 target, 2 lead, 3 target lead, 4 adjacent, then the background.
Variant 0 is the config's nominal values; every other variant draws each `Range` uniformly and
each kind from the role's `random_kinds`, from its own key (vmap over keys).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int, PRNGKeyArray

from diffsense import runtime
from diffsense.scene._datatypes import (
    ADJACENT,
    BACKGROUND,
    EGO,
    KIND_NAMES,
    LEAD,
    TARGET,
    TARGET_LEAD,
)
from diffsense.scene._road import Road, lane_centre_d_m
from diffsense.scene._scenario_config import ScenarioConfig, VehicleModels

_KMH = 1.0 / 3.6
# A vehicle without a lane change gets one (from its lane to the same lane) that ended long ago.
NO_LANE_CHANGE_S = -1e6
NUM_ROLES = 5  # ego, target, lead, target lead, adjacent


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class VehiclePlan:
    """Start state and lane-change plan of V vehicles (leading N for a batch of variants).

    Attributes:
        s_m: [V] arc length of the centre at t = 0 [m].
        speed_mps: [V] speed at t = 0 [m/s].
        d_from_m: [V] lateral offset at t = 0 (a lane centre) [m].
        d_to_m: [V] lateral offset after the lane change (= d_from_m if none) [m].
        lc_start_s: [V] lane-change start time [s].
        lc_duration_s: [V] lane-change duration [s].
        length_m: [V] body length [m].
        width_m: [V] body width [m].
        kind: [V] CAR, VAN or TRUCK.
        role: [V] scenario role.
    """

    s_m: Float[Array, "*N V"]
    speed_mps: Float[Array, "*N V"]
    d_from_m: Float[Array, "*N V"]
    d_to_m: Float[Array, "*N V"]
    lc_start_s: Float[Array, "*N V"]
    lc_duration_s: Float[Array, "*N V"]
    length_m: Float[Array, "*N V"]
    width_m: Float[Array, "*N V"]
    kind: Int[Array, "*N V"]
    role: Int[Array, "*N V"]


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class ScenarioNumbers:
    """A scenario config as arrays, so that one compiled simulation serves every scenario.

    Ranges are rows (nominal, low, high); kinds are ids; roles are in vehicle order
    (ego, target, lead, target lead, adjacent).

    Attributes:
        ego_s_m, ego_speed_mps, lc_start_s, lc_duration_s, background_speed_mps: [3] ranges.
        position_m: [4, 3] ranges of target, lead, target lead, adjacent (see ScenarioConfig).
        relative_speed_mps: [4, 3] ranges, same order.
        nominal_kind: [5] kind ids of the nominal variant.
        allowed_kind: [5, 3] which kinds a randomised variant may draw.
        d_m: [5] start lane centre of each role [m].
        target_ahead_of_lead: [] True when the target starts ahead of the lead, not the ego.
        length_of, width_of: [3] body size of each kind [m].
        background_gap_m, background_spacing_m: [] background placement [m].
        background_d_m: [B] lane centre of each background vehicle [m].
        background_row: [B] its row behind the ego [-].
        background_kind: [] its kind id.
        background_lane_change_s: [] duration of a background vehicle's (MOBIL) lane change [s].
    """

    ego_s_m: Float[Array, " 3"]
    ego_speed_mps: Float[Array, " 3"]
    lc_start_s: Float[Array, " 3"]
    lc_duration_s: Float[Array, " 3"]
    background_speed_mps: Float[Array, " 3"]
    position_m: Float[Array, "4 3"]
    relative_speed_mps: Float[Array, "4 3"]
    nominal_kind: Int[Array, " 5"]
    allowed_kind: Bool[Array, "5 3"]
    d_m: Float[Array, " 5"]
    target_ahead_of_lead: Bool[Array, ""]
    length_of: Float[Array, " 3"]
    width_of: Float[Array, " 3"]
    background_gap_m: Float[Array, ""]
    background_spacing_m: Float[Array, ""]
    background_d_m: Float[Array, " B"]
    background_row: Float[Array, " B"]
    background_kind: Int[Array, ""]
    background_lane_change_s: Float[Array, ""]


def scenario_numbers(cfg: ScenarioConfig, models: VehicleModels, road: Road, dtype=jnp.float32) -> ScenarioNumbers:
    """The arrays of `cfg` (speeds converted to m/s, lanes to lateral offsets)."""
    rng = lambda r, scale=1.0: np.array([r.nominal, r.low, r.high]) * scale  # noqa: E731
    specs = (cfg.target, cfg.lead, cfg.target_lead, cfg.adjacent)
    sizes = [models.size(name) for name in KIND_NAMES]
    bg = cfg.background
    i = np.arange(bg.count)
    lanes_here = int(road.num_lanes)
    lanes = [cfg.ego.lane, cfg.target_lane, cfg.ego.lane, cfg.target_lane, cfg.adjacent_lane]
    allowed = [(cfg.ego.kind,)] + [sp.random_kinds for sp in specs]
    def f(a):  # numpy, then one transfer: no program per array (a traced road stays traced)
        return jnp.asarray(a, dtype) if isinstance(a, jax.core.Tracer) else jax.device_put(np.asarray(a, dtype))

    def put(a, array_dtype):
        return jax.device_put(np.asarray(a, array_dtype))

    def lanes_d_m(lane):
        if isinstance(road.lane_width_m, jax.core.Tracer):
            return lane_centre_d_m(road, lane)
        # lane_centre_d_m in numpy, in the float type JAX would compute it in: the same bits
        # (an exact sum, then one rounded product), and no program
        out = jax.eval_shape(lane_centre_d_m, road, np.asarray(lane)).dtype
        return (np.asarray(lane) + 0.5).astype(out) * np.asarray(road.lane_width_m, out)

    return ScenarioNumbers(
        ego_s_m=f(rng(cfg.ego.s_m)), ego_speed_mps=f(rng(cfg.ego.speed_kmh, _KMH)),
        lc_start_s=f(rng(cfg.lane_change.start_s)), lc_duration_s=f(rng(cfg.lane_change.duration_s)),
        background_speed_mps=f(rng(bg.relative_speed_kmh, _KMH)),
        position_m=f([rng(sp.position_m) for sp in specs]),
        relative_speed_mps=f([rng(sp.relative_speed_kmh, _KMH) for sp in specs]),
        nominal_kind=put([KIND_NAMES.index(k) for k in [cfg.ego.kind] + [sp.kind for sp in specs]], np.int32),
        allowed_kind=put([[name in a for name in KIND_NAMES] for a in allowed], bool),
        d_m=f(lanes_d_m(lanes)), target_ahead_of_lead=put(cfg.target_ahead_of == "lead", bool),
        length_of=f([m.length_m for m in sizes]), width_of=f([m.width_m for m in sizes]),
        background_gap_m=f(bg.gap_m), background_spacing_m=f(bg.spacing_m),
        background_d_m=f(lanes_d_m(i % lanes_here)), background_row=f(i // lanes_here),
        background_kind=put(KIND_NAMES.index(bg.kind), np.int32),
        background_lane_change_s=f(bg.lane_change_duration_s),
    )


def _draw(key: PRNGKeyArray, r: Float[Array, "*R 3"], nominal: Bool[Array, ""]) -> Float[Array, "*R"]:
    value = runtime.uniform(key, r.shape[:-1], r.dtype, r[..., 1], r[..., 2])
    return jnp.where(nominal, r[..., 0], value)


def draw_plan(nums: ScenarioNumbers, key: PRNGKeyArray, nominal: Bool[Array, ""]) -> VehiclePlan:
    """The plan of one variant (`nominal` True: the config's nominal values)."""
    k_kind, k_ego_s, k_ego_v, k_pos, k_rel, k_lc_start, k_lc_dur, k_bg = jax.random.split(key, 8)
    dtype = nums.ego_s_m.dtype
    logits = jnp.where(nums.allowed_kind, 0.0, -jnp.inf)
    kinds = jnp.where(nominal, nums.nominal_kind, jax.random.categorical(k_kind, logits).astype(jnp.int32))
    half = 0.5 * nums.length_of[kinds]
    ego_s = _draw(k_ego_s, nums.ego_s_m, nominal)
    ego_v = _draw(k_ego_v, nums.ego_speed_mps, nominal)
    gap_t, gap_l, gap_tl, off_adj = _draw(k_pos, nums.position_m, nominal)
    lead_s = ego_s + half[0] + gap_l + half[2]
    ref_front = jnp.where(nums.target_ahead_of_lead, lead_s + half[2], ego_s + half[0])
    target_s = ref_front + gap_t + half[1]
    s = jnp.stack([ego_s, target_s, lead_s, target_s + half[1] + gap_tl + half[3], target_s + off_adj])
    rel = jnp.concatenate([jnp.zeros((1,), dtype), _draw(k_rel, nums.relative_speed_mps, nominal)])
    d_to = nums.d_m.at[1].set(nums.d_m[0])  # the target ends in the ego's lane
    lc_start = jnp.full((NUM_ROLES,), NO_LANE_CHANGE_S, dtype).at[1].set(_draw(k_lc_start, nums.lc_start_s, nominal))
    lc_dur = jnp.ones((NUM_ROLES,), dtype).at[1].set(_draw(k_lc_dur, nums.lc_duration_s, nominal))
    roles = jnp.array([EGO, TARGET, LEAD, TARGET_LEAD, ADJACENT], jnp.int32)
    plan = VehiclePlan(s, ego_v + rel, nums.d_m, d_to, lc_start, lc_dur,
                       nums.length_of[kinds], nums.width_of[kinds], kinds, roles)
    if nums.background_d_m.shape[0] == 0:
        return plan
    return _concat(plan, _background(nums, k_bg, nominal, ego_s - half[0], ego_v))


def _background(nums: ScenarioNumbers, key, nominal, ego_rear_s, ego_v) -> VehiclePlan:
    """Lane keepers behind the ego: vehicle i in lane i % lanes, row i // lanes."""
    count = nums.background_d_m.shape[0]
    dtype = nums.background_d_m.dtype
    kind = nums.background_kind
    length = nums.length_of[kind]
    s = ego_rear_s - nums.background_gap_m - 0.5 * length - nums.background_row * nums.background_spacing_m
    rel = _draw(key, jnp.broadcast_to(nums.background_speed_mps, (count, 3)), nominal)
    full = lambda value, dt=dtype: jnp.full((count,), value, dt)  # noqa: E731
    return VehiclePlan(s, ego_v + rel, nums.background_d_m, nums.background_d_m, full(NO_LANE_CHANGE_S),
                       full(nums.background_lane_change_s), full(length), full(nums.width_of[kind]), full(kind, jnp.int32),
                       full(BACKGROUND, jnp.int32))


def _concat(a: VehiclePlan, b: VehiclePlan) -> VehiclePlan:
    return jax.tree.map(lambda x, y: jnp.concatenate([x, y], axis=-1), a, b)
