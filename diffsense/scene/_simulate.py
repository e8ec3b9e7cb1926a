"""Scenario simulation: IDM car following in `lax.scan` at 10 Hz, lane changes by quintic profile.

Lateral motion follows quintic lane changes: the scenario's are planned (`VehiclePlan`), background
vehicles may start their own by MOBIL; the longitudinal motion reacts to them. Each frame every vehicle follows the nearest vehicle ahead whose
body, widened by `lateral_margin_m` on each side, overlaps its own laterally: a follower starts
reacting to a cut-in while the lane changer is still crossing. Speeds advance by the ballistic
update of Treiber & Kanagaraj (2015): v' = v + a dt, s' = s + (v + v') dt / 2, stopping at v = 0.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from diffsense.runtime import InputError, call
from diffsense.scene._background_mobil import lane_change_starts
from diffsense.scene._datatypes import BACKGROUND, Scene
from diffsense.scene._idm import FREE_ROAD_GAP_M, IDMParams, idm_acceleration
from diffsense.scene._lane_change import (
    quintic_lateral_offset_m,
    quintic_lateral_speed_mps,
)
from diffsense.scene._mobil import MOBILParams
from diffsense.scene._road import (
    Road,
    curvature_1pm,
    frenet_to_cartesian,
    lane_index,
    load_road,
)
from diffsense.scene._scenario_config import (
    DriverModel,
    ScenarioConfig,
    VehicleModels,
    check_speed_offset,
    load_vehicle_models,
)
from diffsense.scene._variants import (
    ScenarioNumbers,
    VehiclePlan,
    draw_plan,
    scenario_numbers,
)

SCENE_DT_S = 0.1  # 10 Hz, the rate of the paper's recordings
MIN_DESIRED_SPEED_MPS = 1.0  # a floor only: every shipped scenario starts at highway speed


def leaders(
    s_m: Float[Array, " V"], d_m: Float[Array, " V"], speed_mps: Float[Array, " V"],
    length_m: Float[Array, " V"], width_m: Float[Array, " V"], lateral_margin_m: float,
    heading_to_m: Float[Array, " V"] | None = None, lane_width_m: Float[Array, ""] | float = 0.0,
) -> tuple[Float[Array, " V"], Float[Array, " V"]]:
    """Bumper-to-bumper gap to each vehicle's leader [m] and the leader's speed [m/s].

    j leads i when it is ahead and their bodies (widened by the margin) overlap laterally, or when
    either is changing into the other's lane (`heading_to_m`: the lane centre a vehicle is
    changing into, its own d when not changing): a lane changer and its new follower react to each
    other from the start of the change. No leader: gap FREE_ROAD_GAP_M and the own speed.
    """
    v = s_m.shape[-1]
    ahead_m = s_m[None, :] - s_m[:, None]  # [follower, leader]
    index = jnp.arange(v)
    in_front = (ahead_m > 0) | ((ahead_m == 0) & (index[None, :] > index[:, None]))
    overlap_m = 0.5 * (width_m[None, :] + width_m[:, None]) + 2.0 * lateral_margin_m
    same_lane = jnp.abs(d_m[None, :] - d_m[:, None]) < overlap_m
    if heading_to_m is not None:
        half_lane = 0.5 * lane_width_m
        same_lane |= jnp.abs(heading_to_m[None, :] - d_m[:, None]) < half_lane  # j comes into i's lane
        same_lane |= jnp.abs(d_m[None, :] - heading_to_m[:, None]) < half_lane  # i goes into j's lane
    gap_m = ahead_m - 0.5 * (length_m[None, :] + length_m[:, None])
    gap_m = jnp.where(in_front & same_lane, gap_m, FREE_ROAD_GAP_M)
    nearest = jnp.argmin(gap_m, axis=-1)
    gap = jnp.take_along_axis(gap_m, nearest[:, None], -1)[:, 0]
    return gap, jnp.where(gap < FREE_ROAD_GAP_M, speed_mps[nearest], speed_mps)


def _idm(plan: VehiclePlan, driver: DriverModel) -> IDMParams:
    """Per-vehicle IDM under which every vehicle starts in steady state.

    A vehicle with a leader within reach gets the desired speed `follower_speed_ratio` x its start
    speed and the time headway T that makes its start gap g the equilibrium gap (from a = 0 at
    dv = 0): T = (g sqrt(1 - ratio^-delta) - s0) / v, clipped to [min, max]_time_headway_s.
    A vehicle whose leader is further than that reach (T would exceed the maximum) or absent is
    free: desired speed = its start speed, the config's time headway. Desired speeds are at least
    MIN_DESIRED_SPEED_MPS, so that a vehicle starting at rest is well defined.
    """
    gap, _ = leaders(plan.s_m, plan.d_from_m, plan.speed_mps, plan.length_m, plan.width_m,
                     driver.lateral_margin_m)
    v = jnp.maximum(plan.speed_mps, MIN_DESIRED_SPEED_MPS)
    free_share = (1.0 - driver.follower_speed_ratio ** -driver.accel_exponent) ** 0.5
    headway = (gap * free_share - driver.min_gap_m) / v
    follows = headway <= driver.max_time_headway_s
    return IDMParams(
        desired_speed_mps=jnp.where(follows, driver.follower_speed_ratio * v, v),
        time_headway_s=jnp.where(follows, jnp.maximum(headway, driver.min_time_headway_s), driver.time_headway_s),
        min_gap_m=driver.min_gap_m, max_accel_mps2=driver.max_accel_mps2,
        comfort_decel_mps2=driver.comfort_decel_mps2, accel_exponent=driver.accel_exponent,
    )


def simulate_plan(
    plan: VehiclePlan, road: Road, driver: DriverModel, num_frames: int, dt_s: float = SCENE_DT_S,
    mobil: MOBILParams | None = None, mobil_period_frames: int = 10,
) -> Scene:
    """Simulate one variant for `num_frames` frames [T, V] (frame k is at t = k dt).

    With `mobil`, BACKGROUND vehicles also change lanes by MOBIL (see _background_mobil.py),
    deciding every `mobil_period_frames` frames; without it every lateral motion is the plan's.
    """
    dtype = plan.s_m.dtype
    t = jnp.arange(num_frames, dtype=dtype) * dt_s
    idm = _idm(plan, driver)
    may_change = plan.role == BACKGROUND
    lane_width = jnp.asarray(road.lane_width_m, dtype)

    def decide(s, d, d_to, v, a, lc_start, d_from, t_now):
        free = may_change & (t_now >= lc_start + plan.lc_duration_s)
        starts, to = lane_change_starts(s, d, d_to, v, a, plan.length_m, idm, free, lane_width,
                                        road.num_lanes, mobil)
        return jnp.where(starts, t_now, lc_start), jnp.where(starts, d_to, d_from), jnp.where(starts, to, d_to)

    def step(carry, frame):
        k, t_now = frame
        s, v, lc_start, d_from, d_to = carry
        lc = (lc_start, plan.lc_duration_s, d_from, d_to)
        d = quintic_lateral_offset_m(t_now, *lc)
        # MOBIL changers are announced (their new neighbours react from the start); a scripted
        # cut-in is noticed when the bodies overlap, which keeps the paper's cut-ins as tight.
        announced = may_change & (t_now >= lc_start) & (t_now < lc_start + plan.lc_duration_s)
        gap, lead_v = leaders(s, d, v, plan.length_m, plan.width_m, driver.lateral_margin_m,
                              jnp.where(announced, d_to, d), lane_width)
        a = jnp.maximum(idm_acceleration(v, gap, lead_v, idm), -driver.max_brake_mps2)
        if mobil is not None:  # k is the same in every vmapped variant: a real branch, not a select
            lc_start, d_from, d_to = jax.lax.cond(
                k % mobil_period_frames == 0, decide, lambda *args: (args[5], args[6], args[2]),
                s, d, d_to, v, a, lc_start, d_from, t_now)
        v_next = v + a * dt_s
        stops = v_next < 0.0
        stop_m = v**2 / (2.0 * jnp.where(stops, -a, 1.0))  # a < 0 wherever it is used
        s_next = s + jnp.where(stops, stop_m, 0.5 * (v + v_next) * dt_s)
        frame = (s, v, d, quintic_lateral_speed_mps(t_now, *lc))
        return (s_next, jnp.maximum(v_next, 0.0), lc_start, d_from, d_to), frame

    start = (plan.s_m, plan.speed_mps, plan.lc_start_s, plan.d_from_m, plan.d_to_m)
    _, (s, v, d, d_rate) = jax.lax.scan(step, start, (jnp.arange(num_frames), t))
    x, y, road_angle = frenet_to_cartesian(road, s, d)
    along = v * (1.0 - curvature_1pm(road, s) * d)
    still = (jnp.abs(along) + jnp.abs(d_rate)) == 0.0  # atan2(0, 0) has no gradient
    heading = road_angle + jnp.arctan2(d_rate, jnp.where(still, 1.0, along))
    return Scene(
        s_m=s, d_m=d, x_m=x, y_m=y, heading_rad=heading, road_angle_rad=road_angle, speed_mps=v,
        lane=lane_index(road, d), length_m=plan.length_m, width_m=plan.width_m, kind=plan.kind,
        role=plan.role, present=jnp.ones(plan.s_m.shape, bool), dt_s=dt_s,
    )


def simulate_numbers(nums: ScenarioNumbers, road: Road, driver: DriverModel, key: PRNGKeyArray,
                     num_variants: int, num_frames: int, mobil: MOBILParams | None = None,
                     mobil_period_frames: int = 10) -> Scene:
    """`simulate_scenario` on a scenario's arrays: one compilation per (variants, frames, vehicles)
    shared by every scenario and road (their values are traced, not baked in; the driver model
    and the counts are static)."""
    return call(_simulate_numbers, nums, road, driver, key, num_variants, num_frames, mobil, mobil_period_frames)


def _simulate_numbers(nums: ScenarioNumbers, road: Road, driver: DriverModel, key: PRNGKeyArray,
                      num_variants: int, num_frames: int, mobil: MOBILParams | None,
                      mobil_period_frames: int) -> Scene:
    keys = jax.random.split(key, num_variants)
    nominal = jnp.arange(num_variants) == 0
    plans = jax.vmap(draw_plan, in_axes=(None, 0, 0))(nums, keys, nominal)
    return jax.vmap(lambda p: simulate_plan(p, road, driver, num_frames, mobil=mobil,
                                            mobil_period_frames=mobil_period_frames))(plans)


def simulate_scenario(
    cfg: ScenarioConfig, num_variants: int, key: PRNGKeyArray | int, *, dtype=jnp.float32,
    road: Road | None = None, models: VehicleModels | None = None,
    speed_offset_kmh: float | Float[Array, ""] = 0.0,
) -> Scene:
    """Simulate variant 0 (nominal) and `num_variants - 1` randomised variants: Scene [N, T, V].

    T = round(duration_s / 0.1) + 1 frames (t = 0 .. duration_s); V = 5 + background vehicles.
    `key` is a PRNG key (or an int seed); variant k > 0 depends only on (key, k), so asking for
    more variants keeps the earlier ones. The road and vehicle models default to the shipped ones
    named by the config. Arrays are of `dtype` (float32 by default; float64 needs jax_enable_x64).

    `speed_offset_kmh` moves the ego's start speed (nominal and range) by that much, which is
    the same as editing `ego.speed_kmh` in the config: every other vehicle's start speed is
    relative to the ego's, and desired speeds follow start speeds (see `_idm`). It may be a
    traced value: the scene is differentiable in it (between the simulation's discrete events).
    """
    if not isinstance(num_variants, int) or num_variants < 1:
        raise InputError(f"num_variants must be a positive integer, got {num_variants!r}")
    if isinstance(speed_offset_kmh, (int, float)):  # a traced offset is the caller's to check
        check_speed_offset(cfg, speed_offset_kmh)
    road = load_road(cfg.road) if road is None else road
    models = load_vehicle_models() if models is None else models
    for what, lane in (("ego.lane", cfg.ego.lane), ("target_lane", cfg.target_lane), ("adjacent_lane", cfg.adjacent_lane)):
        if not 0 <= lane < road.num_lanes:
            raise InputError(f"{cfg.name}: {what} {lane} is not a lane of road {cfg.road!r} (0..{road.num_lanes - 1})")
    if isinstance(key, int):
        key = jax.random.key(key)
    num_frames = round(cfg.duration_s / SCENE_DT_S) + 1
    nums = scenario_numbers(cfg, models, road, dtype)
    if not (isinstance(speed_offset_kmh, (int, float)) and speed_offset_kmh == 0):  # + 0 would be 3 programs
        nums = dataclasses.replace(nums, ego_speed_mps=nums.ego_speed_mps + jnp.asarray(speed_offset_kmh, dtype) / 3.6)
    mobil = None
    if cfg.background.count and cfg.background.mobil:
        values = dataclasses.asdict(models.mobil)
        period = max(1, round(values.pop("decision_period_s") / SCENE_DT_S))
        mobil = MOBILParams(**{k: jnp.asarray(x, dtype) for k, x in values.items()})
        return simulate_numbers(nums, road, models.driver, key, num_variants, num_frames, mobil, period)
    return simulate_numbers(nums, road, models.driver, key, num_variants, num_frames)
