"""E(r) of a problem: its scenes simulated (or read), its sensor and predictor built, its draws fixed.

    E = objective(problem)        # a pure equinox Module: E(r) [m], r a dict of named parameters
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from diffsense.metrics import (
    Objective,
    SpeedShiftedScenes,
    make_objective,
    recorded_scenes,
    speed_shifted_scenes,
)
from diffsense.predictors import (
    CastPredictor,
    CSLSTMPredictor,
    load_predictor,
    with_compute_dtype,
)
from diffsense.runtime import InputError, call
from diffsense.scene import RecordedCut, cut_recorded, load_scenario
from diffsense.sensors import Weather, relevance_stand_ins
from diffsense.study._problem import Problem
from diffsense.study._specs import PredictionSpec
from diffsense.tracks import prediction_frames


def _precision(float64: bool):
    # The problem asks for float64: JAX computes in float32 unless x64 is on, which would make
    # dE/dr silently wrong on flat objectives, so it is switched on here.
    if float64 and not jax.config.jax_enable_x64:
        jax.config.update("jax_enable_x64", True)
    return jnp.float64 if float64 else jnp.float32


def _predictor(prediction: PredictionSpec):
    if isinstance(prediction.predictor, str):
        return load_predictor(prediction.predictor or None)
    return prediction.predictor


def _in_dtype(predictor: Any, predictor_dtype: str, dtype) -> Any:
    """The predictor computing in `predictor_dtype` ("auto": the CS-LSTM in float32, the precision
    of its weights; any other predictor in E's own `dtype`)."""
    if predictor_dtype == "auto":
        inner = predictor.inner if isinstance(predictor, CastPredictor) else predictor
        predictor_dtype = "float32" if isinstance(inner, CSLSTMPredictor) else jnp.dtype(dtype).name
    if predictor_dtype == jnp.dtype(dtype).name:
        return predictor
    try:
        return with_compute_dtype(predictor, predictor_dtype)
    except ValueError as e:  # bfloat16 asked of a predictor without LSTM products
        raise InputError(f"predictor_dtype: {e}") from None


@functools.lru_cache(maxsize=4)
def _cut(scenes: str, window_s: float, crossing_at_s: float | None, float64: bool, file_key: tuple) -> RecordedCut:
    return cut_recorded(scenes, window_s=window_s, crossing_at_s=crossing_at_s,
                        dtype=np.float64 if float64 else np.float32)


def recorded_cut(problem: Problem) -> RecordedCut | None:
    """The problem's recording read and cut into scenes (`diffsense.scene.cut_recorded`), host
    arrays only; None for simulated scenarios. A command line reads it first, so that a bad
    file is refused before anything else starts; the objective then takes the same cut, kept
    while the file (its size, times and inode) is unchanged."""
    traffic = problem.traffic
    if traffic.scenes is None:
        return None
    path = Path(traffic.scenes.partition(":")[2])
    try:
        st = path.stat()
        file_key = (st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)
    except OSError as e:
        raise InputError(f"recorded scenes: {path}: {e.strerror}") from None
    return _cut(traffic.scenes, traffic.window_s, traffic.crossing_at_s, problem.prediction.float64, file_key)


def scenes_line(problem: Problem) -> str:
    """The progress line of a job's first step: the scenarios simulated, or the recording read."""
    traffic = problem.traffic
    if traffic.scenes is not None:
        return f"{problem.sensor_kind}: reading {traffic.scenes}"
    return f"{problem.sensor_kind}: simulating {len(traffic.scenarios)} scenarios x {traffic.variants} variants"


def objective(problem: Problem, *, predictor: Any = None, min_vehicles: int = 0,
              progress: Callable[[str], None] | None = None) -> Objective:
    """E(r) of `problem`: the scenarios simulated, its sensor (built once, with the problem) and
    its predictor loaded, every random draw fixed by `problem.seed`. `predictor` (optional)
    replaces `problem.prediction.predictor` (an already loaded one, to load it once for several
    problems); `min_vehicles` pads the simulated scenes' vehicle axis to at least that width
    (absent vehicles, which change no number), so that another objective's programs fit it.
    Recorded scenes are read and cut first, before the predictor loads, and `progress` (optional)
    is told what the recording gave (`diffsense.scene.RecordingSummary.line`)."""
    traffic, prediction, question = problem.traffic, problem.prediction, problem.question
    dtype = _precision(prediction.float64)
    sensor = problem.sensing.built
    cut = recorded_cut(problem)
    if cut is not None and progress is not None:
        progress(cut.summary.line())
    predictor = _predictor(prediction) if predictor is None else predictor
    predictor = _in_dtype(predictor, prediction.predictor_dtype, dtype)
    noise_key = seed_keys(problem.seed)[1]  # [0] is the scenes' (traffic_scenes)
    if cut is not None:
        scenes, index, names, weather = recorded_scenes(
            cut, spec=predictor.spec, sensors=[sensor, *relevance_stand_ins(problem.params)],
            stride_frames=traffic.prediction_stride_frames)
    else:
        shifted, index, names, weather = traffic_scenes(problem, predictor.spec, sensor, dtype, min_vehicles)
        scenes = shifted.base
    frames = prediction_frames(scenes.num_frames, traffic.prediction_stride_frames, predictor.spec, scenes.dt_s)
    return make_objective(scenes, index, frames, sensor, predictor, names=tuple(problem.params),
                          fill=prediction.fill, estimator=question.estimator, key=noise_key, scenario_names=names,
                          question=question.objective, miss_penalty_m2=question.miss_penalty_m2,
                          weather=weather if traffic.weather is None else Weather(**traffic.weather))


def _split_seed(seed: int) -> tuple[jax.Array, jax.Array]:
    return tuple(jax.random.split(jax.random.PRNGKey(seed)))


def seed_keys(seed: int) -> tuple[jax.Array, jax.Array]:
    """(the scenes' key, the detection draws' key) of a problem's `seed`: `jax.random.split` of
    `jax.random.PRNGKey(seed)`, bit for bit, as one compiled program that a warm run loads from
    disk (done op by op, it is five small programs traced and lowered on every run)."""
    return call(_split_seed, seed)


def traffic_scenes(problem: Problem, spec, sensor, dtype, min_vehicles: int = 0
                   ) -> tuple[SpeedShiftedScenes, np.ndarray, tuple[str, ...], Weather]:
    """The problem's simulated scenes as a function of the traffic speed (`objective` evaluates
    them at the problem's own; `diffsense.sensitivity` differentiates them); vehicle axis padded
    to at least `min_vehicles`."""
    scene_key = seed_keys(problem.seed)[0]
    traffic = problem.traffic
    return speed_shifted_scenes(
        traffic.scenarios, traffic.variants, scene_key, spec=spec, sensors=[sensor, *relevance_stand_ins(problem.params)],
        stride_frames=traffic.prediction_stride_frames, background_vehicles=traffic.background_vehicles,
        dtype=dtype, speed_offset_kmh=traffic.traffic_speed_offset_kmh, min_vehicles=min_vehicles)


def memory_estimate_bytes(problem: Problem) -> int:
    """An upper estimate of the fixed data `objective(problem)` allocates [bytes]: scenes and noise
    draws, and the Monte-Carlo estimator's uniforms (N variants x K samples x T frames x V
    vehicles), which dominate for large K. V is bounded by every vehicle a scenario defines."""
    traffic, estimator = problem.traffic, problem.question.estimator
    if traffic.scenes is not None:
        return 0  # a recording's size is known only once it is read
    itemsize = 8 if problem.prediction.float64 else 4
    total = 0
    for name in traffic.scenarios:
        sc = load_scenario(name)
        frames = int(round(sc.duration_s / 0.1)) + 1
        vehicles = 5 + (traffic.background_vehicles or sc.background.count)
        k = estimator.samples if estimator.kind == "mc" else 0
        total += traffic.variants * frames * vehicles * itemsize * (k + 20)  # ~20 per-frame fields
    return total
