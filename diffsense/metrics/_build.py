"""Assemble E(r): simulate the scenarios, keep what each scene requires, fix every random draw.

The paper's scenarios are simulated (variant 0 nominal, the rest randomised from the seed) and
reduced to the vehicles each scene requires: those that can enter the target's social grid
during a history window (sized by the predictor's `InputSpec`) and those that can hide them from
the sensors (sized by the sensors' mountings). Ground-truth predictions are made once here.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from diffsense.config import replace
from diffsense.metrics._datatypes import ObjectiveData
from diffsense.metrics._estimators import EstimatorConfig, mc_uniforms
from diffsense.metrics._objective import QUESTIONS, Objective
from diffsense.metrics._sharding import shard_leading_axis
from diffsense.predictors import InputSpec
from diffsense.runtime import InputError, call
from diffsense.scene import (
    RecordedCut,
    ScenarioConfig,
    Scene,
    load_scenario,
    relevant_selection,
    relevant_vehicles,
    select_vehicles,
    simulate_scenario,
)
from diffsense.sensors import CLEAR, Sensor, Weather
from diffsense.tracks import (
    FillPolicy,
    build_inputs,
    flatten_instants,
    ground_truth_detections,
    prediction_frames,
    true_future,
)

PAPER_SCENARIOS: tuple[str, ...] = ("sc01", "sc02", "sc03", "sc04", "sc05", "sc06")


def relevance_reach(spec: InputSpec, sensors: Sequence[Sensor]) -> dict[str, float]:
    """The keywords of `scene.relevant_vehicles` for a predictor's spec and the ego's sensors."""
    return dict(history_s=spec.history_s, grid_half_length_m=spec.grid_half_length_m,
                sensor_reach_m=max(s.mount_x_m for s in sensors))


def pad_vehicles(scene: Scene, width: int) -> Scene:
    """Pad the vehicle axis [N, T, V] to `width` with absent vehicles: those `select_vehicles`
    adds (present False, role BACKGROUND, 1 km behind the ego), so padding means one thing."""
    extra = width - scene.num_vehicles
    if extra == 0:
        return scene
    slots = np.arange(width)
    real = slots < scene.num_vehicles
    shape = scene.s_m.shape[:-2] + (width,)
    return select_vehicles(scene, np.broadcast_to(np.where(real, slots, 0), shape), np.broadcast_to(real, shape))


def _scenario(name: str, background_vehicles: int) -> ScenarioConfig:
    scenario = load_scenario(name)
    if background_vehicles:
        scenario = replace(scenario, background=replace(scenario.background, count=background_vehicles))
    return scenario


def _concat_scenes(scenes: Sequence[Scene], width: int) -> Scene:
    return call(_concat_padded, tuple(scenes), width)  # one program, not one per field


def _concat_padded(scenes: tuple[Scene, ...], width: int) -> Scene:
    return jax.tree.map(lambda *a: jnp.concatenate(a), *[pad_vehicles(s, width) for s in scenes])


def simulate_scenes(
    scenarios: Sequence[str], variants: int, key: jax.Array, *, spec: InputSpec, sensors: Sequence[Sensor],
    stride_frames: int = 4, background_vehicles: int = 0, dtype=jnp.float64, speed_offset_kmh: float = 0.0,
) -> tuple[Scene, np.ndarray, tuple[str, ...], Weather]:
    """All variants of all scenarios, reduced to their relevant vehicles: Scene [N, T, V],
    the scenario index of each variant [N], the scenario names, and each variant's weather
    (the scenario TOML's `[weather]`; leaves [N]). `speed_offset_kmh` moves every scenario's
    traffic speed (`diffsense.scene.simulate_scenario`)."""
    shifted, index, names, weather = speed_shifted_scenes(
        scenarios, variants, key, spec=spec, sensors=sensors, stride_frames=stride_frames,
        background_vehicles=background_vehicles, dtype=dtype, speed_offset_kmh=speed_offset_kmh)
    return shifted.base, index, names, weather


class SpeedShiftedScenes(eqx.Module):
    """`simulate_scenes` as a function of the traffic speed: `self(offset_kmh)` re-simulates
    every scenario with its speeds moved by `offset_kmh` more than `base` (traced values are
    fine: the scenes are differentiable in it) and keeps the vehicles `base` kept, so the batch
    keeps its shape. Relevance is decided at the base speed: its margins (see
    `diffsense.scene.relevant_vehicles`) cover what a small speed change can bring into the grid.
    """

    base: Scene
    keys: tuple[jax.Array, ...]
    selections: tuple[tuple[jax.Array, jax.Array], ...]
    configs: tuple[ScenarioConfig, ...] = eqx.field(static=True)
    variants: int = eqx.field(static=True)
    base_offset_kmh: float = eqx.field(static=True)
    width: int = eqx.field(static=True)
    dtype: Any = eqx.field(static=True)

    def __call__(self, offset_kmh) -> Scene:
        total = self.base_offset_kmh + offset_kmh
        sims = [select_vehicles(simulate_scenario(cfg, self.variants, key, dtype=self.dtype, speed_offset_kmh=total),
                                *sel) for cfg, key, sel in zip(self.configs, self.keys, self.selections)]
        return _concat_scenes(sims, self.width)


def speed_shifted_scenes(
    scenarios: Sequence[str], variants: int, key: jax.Array, *, spec: InputSpec, sensors: Sequence[Sensor],
    stride_frames: int = 4, background_vehicles: int = 0, dtype=jnp.float64, speed_offset_kmh: float = 0.0,
    min_vehicles: int = 0,
) -> tuple[SpeedShiftedScenes, np.ndarray, tuple[str, ...], Weather]:
    """`simulate_scenes`'s results with the scenes as a `SpeedShiftedScenes` (its `base` the batch).
    `min_vehicles` pads the vehicle axis to at least that width (absent vehicles): another seed's
    batch padded to an objective's width runs that objective's compiled programs."""
    configs = tuple(_scenario(name, background_vehicles) for name in scenarios)
    keys = call(_scenario_keys, key, len(configs))
    scenes, selections = [], []
    for scenario, k in zip(configs, keys):
        sim = simulate_scenario(scenario, variants, k, dtype=dtype, speed_offset_kmh=speed_offset_kmh)
        frames = prediction_frames(sim.num_frames, stride_frames, spec, sim.dt_s)
        selections.append(relevant_selection(sim, frames, **relevance_reach(spec, sensors)))
        scenes.append(select_vehicles(sim, *selections[-1]))
    lengths = {s.num_frames for s in scenes}
    if len(lengths) != 1:
        raise InputError(f"scenarios must have the same duration to be pooled, got {sorted(lengths)} frames")
    width = max(min_vehicles, *(s.num_vehicles for s in scenes))
    weather = Weather(rain_mm_h=np.repeat([c.weather.rain_mm_h for c in configs], variants),
                      fog_visibility_m=np.repeat([c.weather.fog_visibility_m or np.inf for c in configs], variants))
    shifted = SpeedShiftedScenes(_concat_scenes(scenes, width), keys, tuple(selections), configs, variants,
                                 float(speed_offset_kmh), width, dtype)
    return shifted, np.repeat(np.arange(len(configs)), variants), tuple(c.name for c in configs), weather


def recorded_scenes(
    cut: RecordedCut, *, spec: InputSpec, sensors: Sequence[Sensor], stride_frames: int = 4,
) -> tuple[Scene, np.ndarray, tuple[str, ...], Weather]:
    """The scenes of a cut recording (`diffsense.scene.cut_recorded`, cut in `dtype`), each its own
    scenario of one variant named FILE#i, reduced to their relevant vehicles like simulated ones;
    clear weather."""
    kept = []
    for scene in cut.scenes:
        # device_put moves the host arrays as they are; jnp.asarray would compile once per scene shape.
        scene = jax.tree.map(jax.device_put, scene)
        frames = prediction_frames(scene.num_frames, stride_frames, spec, scene.dt_s)
        kept.append(relevant_vehicles(scene, frames, **relevance_reach(spec, sensors)))
    width = max(s.num_vehicles for s in kept)
    batch = _concat_padded(tuple(jax.tree.map(lambda a: a[None], s) for s in kept), width)
    stem = Path(cut.summary.path).name
    n = len(kept)
    return (batch, np.arange(n), tuple(f"{stem}#{i}" for i in range(n)),
            Weather(rain_mm_h=np.zeros(n), fog_visibility_m=np.full(n, np.inf)))


def ground_truth_predictions(scenes: Scene, frames, fill: FillPolicy, predictor) -> jax.Array:
    """The predictor's output from ground-truth histories at every instant: [N, I, F, 2] [m]."""
    return call(_ground_truth_predictions, scenes, tuple(int(f) for f in np.asarray(frames)), fill, predictor)


def _scenario_keys(key: jax.Array, count: int) -> tuple[jax.Array, ...]:
    """`jax.random.fold_in(key, i)` for each scenario i, as one program (`call` keeps it)."""
    return tuple(jax.random.fold_in(key, i) for i in range(count))


def _variant_draws(key: jax.Array, n: int, samples: int, shape: tuple[int, ...], dtype: str):
    """(measurement-noise keys [n, 2], Monte-Carlo uniforms [n, samples, *shape]) of `key`, as
    one program (`call` keeps it): op by op they were six small programs on every run."""
    noise_key, mc_key = jax.random.split(key)
    uniform = jax.vmap(lambda kk: mc_uniforms(kk, samples, shape, jnp.dtype(dtype)))(jax.random.split(mc_key, n))
    return jax.random.split(noise_key, n), uniform


def _true_futures(scenes: Scene, frames: tuple[int, ...], spec: InputSpec) -> jax.Array:
    """The target's true future at every instant of every variant: [N, I, F, 2] [m] (one program)."""
    return call(_true_futures_program, scenes, frames, spec)


def _true_futures_program(scenes: Scene, frames: tuple[int, ...], spec: InputSpec) -> jax.Array:
    return jax.vmap(lambda s: true_future(s, jnp.asarray(frames), spec))(scenes)


# One program, inputs and prediction together: built op by op, the inputs alone were some sixty
# small programs, each traced, lowered and looked up in the compilation cache on every run.
def _ground_truth_predictions(scenes: Scene, frames: tuple[int, ...], fill: FillPolicy, predictor) -> jax.Array:
    at = jnp.asarray(frames)
    gt = jax.vmap(lambda s: build_inputs(s, ground_truth_detections(s), at, fill, predictor.spec))(scenes)
    return predictor(flatten_instants(gt)).reshape(scenes.x_m.shape[0], len(frames), -1, 2)


def with_scenes(E: Objective, scenes: Scene) -> Objective:
    """E over other scenes of the same shape as E's real variants [n, T, V] (e.g. the same
    scenarios at another traffic speed): ground truth, true future and ground-truth predictions
    recomputed from them (jit-able, differentiable in the scenes); noise keys, Monte-Carlo draws,
    weights and weather kept. Padding rows added for sharding repeat the last scene, as before."""
    pad = E.data.scenes.x_m.shape[0] - scenes.x_m.shape[0]
    if pad:
        scenes = jax.tree.map(lambda a: jnp.concatenate([a, jnp.repeat(a[-1:], pad, axis=0)]), scenes)
    fut = _true_futures(scenes, E.frames, E.spec)
    gt_pred = ground_truth_predictions(scenes, np.asarray(E.frames), E.fill, E.predictor)
    return eqx.tree_at(lambda o: (o.data.scenes, o.data.gt_pred, o.data.true_fut), E,
                       (scenes, gt_pred.astype(E.dtype), fut.astype(E.dtype)))


def with_variants(E: Objective, index) -> Objective:
    """E over the variants `index` [M] of E's own (repeats allowed, any order): each keeps its
    scenes, ground truth, noise key, Monte-Carlo draws, weight and weather, so E over a bootstrap
    resample is E of that resample's variants, evaluated afresh (`diffsense.metrics.bootstrap_ci`
    reweights sums instead)."""
    at = jnp.asarray(np.asarray(index, np.int32))
    data = jax.tree.map(lambda a: a[at], E.data)
    return eqx.tree_at(lambda o: (o.data, o.weather), E, (data, jax.tree.map(lambda a: a[at], E.weather)))


def make_objective(
    scenes: Scene,
    scenario: np.ndarray,
    frames: np.ndarray,
    sensor: Sensor,
    predictor,
    *,
    names: Sequence[str],
    fill: FillPolicy = "hold",
    estimator: EstimatorConfig = EstimatorConfig(),
    key: jax.Array | None = None,
    scenario_names: Sequence[str] | None = None,
    shard: bool = True,
    question: str = "eq12",
    miss_penalty_m2: float = 100.0,
    weather: Weather = CLEAR,
) -> Objective:
    """E(r) of `sensor` and `predictor` over the scene variants `scenes` [N, T, V].

    `key` fixes every random draw (measurement noise, Monte-Carlo uniforms): same key, same E(r).
    `question` is "eq12" or "tracked", `miss_penalty_m2` the price of an instant without a track
    in the latter (see `Objective`). `weather`: scalars for every variant, or leaves [N].
    Ground-truth predictions are computed here, once. With several JAX devices the variants
    are sharded over them (padded with zero-weight copies to a multiple of the device count);
    with one device nothing changes.
    """
    for name in names:
        sensor.spec(name)
    if question not in QUESTIONS:
        raise InputError(f"unknown objective {question!r} (known: {', '.join(QUESTIONS)})")
    if not (np.isfinite(miss_penalty_m2) and miss_penalty_m2 >= 0):
        raise InputError(f"miss_penalty_m2 must be a finite number >= 0, got {miss_penalty_m2}")
    frames = np.asarray(frames, dtype=np.int32)
    scenario = jax.device_put(np.asarray(scenario, np.int32))  # no program per host array
    n = scenario.shape[0]
    dtype = scenes.x_m.dtype
    key = jax.random.PRNGKey(0) if key is None else key
    # Random draws are made per real variant before any padding, so sharding never changes them.
    k = estimator.samples if estimator.kind == "mc" else 0
    noise_keys, uniform = call(_variant_draws, key, n, k, tuple(scenes.x_m.shape[1:]), jnp.dtype(dtype).name)
    fut = _true_futures(scenes, tuple(int(f) for f in frames), predictor.spec)
    fixed = (scenes, scenario, jax.device_put(np.ones((n,), dtype)), noise_keys, uniform, fut)
    if shard:
        fixed = shard_leading_axis(fixed, pad_weight_index=2)
    scenes, scenario, weight, noise_keys, uniform, fut = fixed
    gt_pred = ground_truth_predictions(scenes, frames, fill, predictor)
    data = ObjectiveData(scenes=scenes, scenario=scenario, weight=weight, gt_pred=gt_pred,
                         true_fut=fut.astype(gt_pred.dtype), noise_key=noise_keys, mc_uniform=uniform)
    if scenario_names is None:
        scenario_names = tuple(f"scenario{i}" for i in range(int(jnp.max(scenario)) + 1))
    weather = jax.tree.map(lambda v: jnp.broadcast_to(jnp.asarray(v, dtype), (n,)), weather)
    if shard:
        weather = shard_leading_axis(weather)
    return Objective(data=data, sensor=sensor, predictor=predictor, weather=weather, names=tuple(names),
                     frames=tuple(int(f) for f in frames), fill=fill, estimator=estimator,
                     scenario_names=tuple(scenario_names), question=question, miss_penalty_m2=float(miss_penalty_m2))
