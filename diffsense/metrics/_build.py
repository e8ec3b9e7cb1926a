"""Assemble E(r) for a named sensor parameter from configs: scenes, sensor, predictor.

This is where the pipeline stages meet: the paper's scenarios are simulated (variant 0 nominal,
the rest randomised from the seed), reduced to the vehicles each scene requires, the sensor is
loaded with its defaults and one parameter left free, and the CS-LSTM is loaded.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Literal

import jax
import jax.numpy as jnp
import numpy as np

from diffsense.config import replace
from diffsense.errors import InputError
from diffsense.metrics._estimators import EstimatorConfig
from diffsense.metrics._objective import Objective, make_objective
from diffsense.predictors import Predictor, load_predictor, predict_mean
from diffsense.scene import Scene, load_scenario, relevant_vehicles, simulate_scenario
from diffsense.sensors import ParamSpec, detect, load_config, param_specs, with_param
from diffsense.tracks import PredictorInputs, prediction_frames

PAPER_SCENARIOS: tuple[str, ...] = ("sc01", "sc02", "sc03", "sc04", "sc05", "sc06")


@dataclasses.dataclass(frozen=True)
class ProblemConfig:
    """What E(r) is computed over.

    Attributes:
        sensor: "radar" or "camera".
        param: the free parameter, e.g. "hfov_deg" ("hfov" is accepted as a short name).
        scenarios: scenario names or TOML paths.
        variants: scene variants per scenario (variant 0 nominal) [-].
        model: predictor weights: "" for the shipped ones, else a .msgpack or PyTorch checkpoint path.
        fill: missing-detection policy, "zero", "hold" or "interp".
        estimator: how detection uncertainty enters (mean-field, Monte-Carlo, hard).
        seed: fixes scene variants, measurement noise and Monte-Carlo draws.
        prediction_stride_frames: one prediction instant every this many 10 Hz frames [-].
        background_vehicles: if > 0, replaces every scenario's count of far background
            vehicles (they never reach the target's grid; the cost must not grow with them).
        float64: compute E(r) in float64 (the solver's default) rather than float32.
    """

    sensor: Literal["radar", "camera"] = "radar"
    param: str = "hfov_deg"
    scenarios: tuple[str, ...] = PAPER_SCENARIOS
    variants: int = 8
    model: str = ""
    fill: Literal["zero", "hold", "interp"] = "hold"
    estimator: EstimatorConfig = EstimatorConfig()
    seed: int = 0
    prediction_stride_frames: int = 4
    background_vehicles: int = 0
    float64: bool = True

    def __post_init__(self):
        if self.variants < 1:
            raise InputError(f"variants must be >= 1, got {self.variants}")
        if not self.scenarios:
            raise InputError("at least one scenario is needed")
        if self.background_vehicles < 0:
            raise InputError(f"background_vehicles must be >= 0, got {self.background_vehicles}")
        if self.prediction_stride_frames < 1:
            raise InputError(f"prediction_stride_frames must be >= 1, got {self.prediction_stride_frames}")


def resolve_param(sensor: str, name: str) -> ParamSpec:
    """The spec of a sensor parameter by full ("hfov_deg") or short ("hfov") name."""
    specs = {s.name: s for s in param_specs(sensor)}
    if name in specs:
        return specs[name]
    short = {s.name.rsplit("_", 1)[0]: s for s in specs.values()}
    if name in short:
        return short[name]
    known = ", ".join(f"{k} ({v.name})" for k, v in short.items())
    raise InputError(f"unknown {sensor} parameter {name!r} (known: {known})")


def check_interval(spec: ParamSpec, lo: float, hi: float) -> None:
    """Refuse a reversed interval or one outside the parameter's physical domain."""
    if not (np.isfinite(lo) and np.isfinite(hi)):
        raise InputError(f"interval bounds must be finite numbers, got {lo} {hi}")
    if not lo < hi:
        raise InputError(f"interval must have LO < HI, got {lo:g} {hi:g}")
    for value in (lo, hi):
        if not spec.contains(value):
            raise InputError(f"interval {lo:g} {hi:g} is outside the domain of {spec.name}: {spec.describe()}")


def _pad_vehicles(scene: Scene, width: int) -> Scene:
    """Pad the vehicle axis [N, T, V] to `width` with absent vehicles (present False)."""
    extra = width - scene.num_vehicles
    if extra == 0:
        return scene

    def pad(a, fill):
        widths = [(0, 0)] * (a.ndim - 1) + [(0, extra)]
        return jnp.pad(a, widths, constant_values=fill)

    # Absent vehicles sit 1 km behind the ego so no geometric test ever sees them.
    far = scene.s_m[..., :1] - 1000.0
    fields = {f.name: getattr(scene, f.name) for f in dataclasses.fields(scene) if f.name != "dt_s"}
    out = {k: pad(v, 0) for k, v in fields.items()}
    out["present"] = pad(scene.present, False)
    for name in ("s_m", "x_m"):
        out[name] = jnp.concatenate([fields[name], jnp.broadcast_to(far, far.shape[:-1] + (extra,))], axis=-1)
    out["length_m"] = pad(scene.length_m, 4.5)
    out["width_m"] = pad(scene.width_m, 1.8)
    return Scene(**out, dt_s=scene.dt_s)


def simulate_scenes(cfg: ProblemConfig, key: jax.Array) -> tuple[Scene, np.ndarray, list[str]]:
    """All variants of all scenarios, reduced to their relevant vehicles: Scene [N, T, V]."""
    dtype = jnp.float64 if cfg.float64 else jnp.float32
    scenes, names = [], []
    for i, name in enumerate(cfg.scenarios):
        scenario = load_scenario(name)
        if cfg.background_vehicles:
            scenario = replace(scenario, background=replace(scenario.background, count=cfg.background_vehicles))
        sim = simulate_scenario(scenario, cfg.variants, jax.random.fold_in(key, i), dtype=dtype)
        frames = prediction_frames(sim.num_frames, cfg.prediction_stride_frames)
        scenes.append(relevant_vehicles(sim, frames))
        names.append(scenario.name)
    lengths = {s.num_frames for s in scenes}
    if len(lengths) != 1:
        raise InputError(f"scenarios must have the same duration to be pooled, got {sorted(lengths)} frames")
    width = max(s.num_vehicles for s in scenes)
    batch = jax.tree.map(lambda *a: jnp.concatenate(a), *[_pad_vehicles(s, width) for s in scenes])
    scenario_index = np.repeat(np.arange(len(scenes)), cfg.variants)
    return batch, scenario_index, names


def _predict(predictor: Predictor, inputs: PredictorInputs):
    return predict_mean(predictor, inputs.hist, inputs.nbr_hist, inputs.nbr_slot, inputs.nbr_weight)


@dataclasses.dataclass(frozen=True)
class Problem:
    """A built E(r) and what it was built from."""

    objective: Objective
    config: ProblemConfig
    param: ParamSpec
    scenario_names: list[str]
    sensor_config: Any


def build_problem(cfg: ProblemConfig, predictor: Predictor | None = None) -> Problem:
    """E(r) for `cfg.param` of `cfg.sensor` over the configured scenes (see `ProblemConfig`)."""
    spec = resolve_param(cfg.sensor, cfg.param)
    sensor_config = load_config(cfg.sensor)
    base = sensor_config.params
    predictor = load_predictor(cfg.model or None) if predictor is None else predictor
    key = jax.random.PRNGKey(cfg.seed)
    scene_key, noise_key = jax.random.split(key)
    scenes, scenario_index, names = simulate_scenes(cfg, scene_key)

    def detect_fn(scene, r, tau, mode, k):
        params = with_param(base, spec.name, r)
        return detect(scene, params, sensor_config, k, mode=mode, temperature=tau)

    frames = prediction_frames(scenes.num_frames, cfg.prediction_stride_frames)
    objective = make_objective(scenes, scenario_index, frames, detect_fn, _predict, predictor,
                               fill=cfg.fill, estimator=cfg.estimator, key=noise_key,
                               num_scenarios=len(names))
    return Problem(objective=objective, config=cfg, param=spec, scenario_names=names,
                   sensor_config=sensor_config)
