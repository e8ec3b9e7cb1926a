"""The library's entry points: `objective(problem)` and `optimise(problem)` (the main job).

    E = objective(problem)        # a pure equinox Module: E(r) [m], r a dict of named parameters
    result = optimise(problem)    # stepped sweep + continuous solve + what the figures draw

`python -m diffsense.optimise` calls `optimise` and writes `Result.to_json()` and the figures.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from diffsense import _line_report as report
from diffsense import config as cfgio
from diffsense._answer import near_optimal
from diffsense._domain import domain_check, domain_note
from diffsense._executables import call
from diffsense._problem import Problem
from diffsense._result import Result
from diffsense._timing import CompileClock
from diffsense.metrics import (
    Objective,
    SpeedShiftedScenes,
    is_deterministic,
    make_objective,
    recorded_scenes,
    speed_shifted_scenes,
)
from diffsense.predictors import CastPredictor, CSLSTMPredictor, load_predictor, with_compute_dtype
from diffsense.sensors import Weather
from diffsense.sensors._mount import relevance_stand_ins
from diffsense.solve import Evaluator, default_steps, hard_grid_solve, solve
from diffsense.tracks import prediction_frames

Progress = Callable[[str], None]


def _precision(float64: bool):
    # The problem asks for float64: JAX computes in float32 unless x64 is on, which would make
    # dE/dr silently wrong on flat objectives, so it is switched on here.
    if float64 and not jax.config.jax_enable_x64:
        jax.config.update("jax_enable_x64", True)
    return jnp.float64 if float64 else jnp.float32


def _predictor(problem: Problem):
    if isinstance(problem.predictor, str):
        return load_predictor(problem.predictor or None)
    return problem.predictor


def _in_dtype(predictor: Any, predictor_dtype: str, dtype) -> Any:
    """The predictor computing in `predictor_dtype` ("auto": the CS-LSTM in float32, the precision
    of its weights; any other predictor in E's own `dtype`)."""
    if predictor_dtype == "auto":
        inner = predictor.inner if isinstance(predictor, CastPredictor) else predictor
        predictor_dtype = "float32" if isinstance(inner, CSLSTMPredictor) else jnp.dtype(dtype).name
    return with_compute_dtype(predictor, predictor_dtype) if predictor_dtype != jnp.dtype(dtype).name else predictor


def objective(problem: Problem, *, predictor: Any = None) -> Objective:
    """E(r) of `problem`: the scenarios simulated, the sensor and predictor loaded, every random
    draw fixed by `problem.seed`. `predictor` (optional) replaces `problem.predictor` (an
    already loaded one, to load it once for several problems)."""
    dtype = _precision(problem.float64)
    sensor = problem.make_sensor()
    predictor = _predictor(problem) if predictor is None else predictor
    predictor = _in_dtype(predictor, problem.predictor_dtype, dtype)
    noise_key = seed_keys(problem.seed)[1]  # [0] is the scenes' (traffic_scenes)
    if problem.scenes is not None:
        scenes, index, names, weather = recorded_scenes(
            problem.scenes, spec=predictor.spec, sensors=[sensor, *relevance_stand_ins(problem.params)],
            stride_frames=problem.prediction_stride_frames,
            dtype=dtype)
    else:
        shifted, index, names, weather = traffic_scenes(problem, predictor.spec, sensor, dtype)
        scenes = shifted.base
    frames = prediction_frames(scenes.num_frames, problem.prediction_stride_frames, predictor.spec, scenes.dt_s)
    return make_objective(scenes, index, frames, sensor, predictor, names=tuple(problem.params),
                          fill=problem.fill, estimator=problem.estimator, key=noise_key, scenario_names=names,
                          question=problem.objective, miss_penalty_m2=problem.miss_penalty_m2,
                          weather=weather if problem.weather is None else Weather(**problem.weather))


def _split_seed(seed: int) -> tuple[jax.Array, jax.Array]:
    return tuple(jax.random.split(jax.random.PRNGKey(seed)))


def seed_keys(seed: int) -> tuple[jax.Array, jax.Array]:
    """(the scenes' key, the detection draws' key) of a problem's `seed`: `jax.random.split` of
    `jax.random.PRNGKey(seed)`, bit for bit, as one compiled program that a warm run loads from
    disk (done op by op, it is five small programs traced and lowered on every run)."""
    return call(_split_seed, seed)


def traffic_scenes(problem: Problem, spec, sensor, dtype) -> tuple[SpeedShiftedScenes, np.ndarray, tuple[str, ...], Weather]:
    """The problem's simulated scenes as a function of the traffic speed (`objective` evaluates
    them at the problem's own; `diffsense.sensitivity` differentiates them)."""
    scene_key = seed_keys(problem.seed)[0]
    return speed_shifted_scenes(
        problem.scenarios, problem.variants, scene_key, spec=spec, sensors=[sensor, *relevance_stand_ins(problem.params)],
        stride_frames=problem.prediction_stride_frames, background_vehicles=problem.background_vehicles,
        dtype=dtype, speed_offset_kmh=problem.traffic_speed_offset_kmh)


def _config(problem: Problem) -> dict[str, Any]:
    fields = {f.name: getattr(problem, f.name) for f in dataclasses.fields(problem)}
    fields["sensor"] = problem.sensor_kind
    if not isinstance(problem.predictor, str):
        fields["predictor"] = type(problem.predictor).__name__
    fields["params"] = {k: list(v) for k, v in problem.params.items()}
    if isinstance(problem.sensor, tuple):
        fields["sensor"] = [s if isinstance(s, str) else s.kind for s in problem.sensor]
    return cfgio.to_dict(fields)


def planned_evaluations(problem: Problem, sweep_soft: bool = True) -> int:
    """How many objective evaluations `optimise` plans (sweep, solve budget, figures, dense check).
    `sweep_soft` False: the sweep reads E_soft off its E_ref (straight-through under a
    probabilistic law), one program per step instead of two."""
    (lo, hi), = problem.params.values()
    steps = len(problem.steps) if problem.steps is not None else len(default_steps(lo, hi))
    dense = 0 if problem.dense_check is None else int(math.ceil((hi - lo) / problem.dense_check - 1e-9)) + 1
    sweep_programs = (2 if sweep_soft else 1) * steps
    return sweep_programs + problem.solve.max_evaluations + 2 + problem.extra_curve_points * 2 + dense


def memory_estimate_bytes(problem: Problem) -> int:
    """An upper estimate of the fixed data `objective(problem)` allocates [bytes]: scenes and noise
    draws, and the Monte-Carlo estimator's uniforms (N variants x K samples x T frames x V
    vehicles), which dominate for large K. V is bounded by every vehicle a scenario defines."""
    from diffsense.scene import load_scenario

    if problem.scenes is not None:
        return 0  # a recording's size is known only once it is read
    itemsize = 8 if problem.float64 else 4
    total = 0
    for name in problem.scenarios:
        sc = load_scenario(name)
        frames = int(round(sc.duration_s / 0.1)) + 1
        vehicles = 5 + (problem.background_vehicles or sc.background.count)
        k = problem.estimator.samples if problem.estimator.kind == "mc" else 0
        total += problem.variants * frames * vehicles * itemsize * (k + 20)  # ~20 per-frame fields
    return total


def optimise(problem: Problem, *, E: Objective | None = None, predictor: Any = None, figures: bool = True,
             progress: Progress | None = None, on_evaluation: Callable[[dict], None] | None = None,
             sensitivity: tuple[str, ...] = (), distributed: bool | Mapping[str, Any] = False) -> Result:
    """The main job: argmin of E over the problem's box, cross-checked by the stepped sweep.

    One-parameter problems: the stepped sweep on E_hard, then the continuous solve inside the
    best step's bracket (`diffsense.solve.solve`; the hard estimator searches an inner grid
    instead), the answer chosen on E_hard. With `figures`, the evaluations the figures draw
    are made too (`Result.curves`); with `problem.dense_check`, a dense grid of the reference E_ref.
    `E` reuses an already built `objective(problem)`; `predictor` an already loaded predictor.
    `sensitivity` names ODD parameters ("rain_mm_h", ...) whose dr*/dtheta is computed at the
    answer (`diffsense.sensitivity`) and kept in `Result.sensitivity`.
    `distributed` (True, or {"coordinator", "num_processes", "process_id"}) joins a multi-process
    run first (`diffsense._distributed.initialize`; before any JAX computation): every process
    calls `optimise` with the same problem and gets the same result.
    `on_evaluation(event)` is called after every objective evaluation the run makes, with
    {"kind": "soft" | "hard" | "reference", "E_m", "tau", "done", "planned"} (for progress displays).
    """
    say = progress or (lambda message: None)
    if distributed:
        from diffsense._distributed import initialize

        initialize(**(dict(distributed) if isinstance(distributed, Mapping) else {}))
    if sensitivity:  # refused before any work, not after the solve
        from diffsense._sensitivity import check_theta

        check_theta(problem, sensitivity)
    if len(problem.params) != 1 or problem.cost_weight > 0:
        from diffsense._suite_solve import optimise_box

        return optimise_box(problem, E, predictor, say, on_evaluation)
    out, E = _optimise_line(problem, E, predictor, figures, say, on_evaluation)
    if sensitivity:
        from diffsense._sensitivity import sensitivity as implicit

        say(f"{problem.sensor_kind}: dr*/dtheta for {', '.join(sensitivity)} (implicit function theorem)")
        out = dataclasses.replace(out, sensitivity=implicit(problem, out, sensitivity, E=E))
    return out


def _evaluator(problem: Problem, E: Objective | None, predictor: Any, say: Progress,
               on_evaluation: Callable[[dict], None] | None, figures: bool) -> tuple[Objective, Evaluator]:
    """The problem's objective (built unless given) and its memoising, counting evaluator."""
    say(f"{problem.sensor_kind}: simulating {len(problem.scenarios)} scenarios x {problem.variants} variants; "
        "ground-truth predictions")
    E = objective(problem, predictor=predictor) if E is None else E
    # the figures draw E_soft and its slope at the sweep's steps: value-and-gradients either way
    planned = planned_evaluations(problem, sweep_soft=figures or not _soft_value_is_e_ref(E))

    def counted(kind: str, e_m: float, tau: float) -> None:
        if on_evaluation is not None:
            done = sum(ev.counts.values()) + ev.reference_count
            on_evaluation({"kind": kind, "E_m": e_m, "tau": tau, "done": done, "planned": planned})

    ev = Evaluator(E, progress=counted)
    return E, ev


def _soft_value_is_e_ref(E: Objective) -> bool:
    """Straight-through under a probabilistic law: E_soft's value is E_ref itself, so the sweep
    reads it off its E_ref evaluation rather than running a value-and-gradient program, and
    every gradient evaluation's point is an answer candidate."""
    return E.estimator_kind == "straight-through" and not is_deterministic(E.sensor)


def _solve_line(ev: Evaluator, problem: Problem, on_hard: bool) -> Any:
    """The sweep and the continuous solve (the inner hard grid for the hard estimator) of a
    one-parameter problem, the answer judged on E_hard or, under a probabilistic law, E_ref."""
    (_, (lo, hi)), = problem.params.items()
    if problem.estimator.kind == "hard":
        return hard_grid_solve(ev.e_hard, (lo, hi), steps=problem.steps, max_evaluations=problem.solve.max_evaluations)
    e2_soft, e_hard = ev.solver_fns(jnp.float64 if problem.solve.dtype == "float64" else jnp.float32)
    # Under a probabilistic detection law the sweep, the answer and the polish are judged on
    # E_ref, the expectation the estimator approximates; under the threshold law E_ref is E_hard.
    e_answer = e_hard if on_hard else (lambda r: ev.e_reference(float(r)))
    return solve(e2_soft, e_answer, (lo, hi), steps=problem.steps, config=problem.solve,
                 value_and_grad=ev.host_value_and_grad, answer_name="E_hard" if on_hard else "E_ref",
                 soft_value_is_answer=_soft_value_is_e_ref(ev.objective))


def _optimise_line(problem: Problem, E: Objective | None, predictor: Any, figures: bool, say: Progress,
                   on_evaluation: Callable[[dict], None] | None) -> tuple[Result, Objective]:
    """`optimise` of a one-parameter problem (its docstring), and the objective it built or was given."""
    (name, (lo, hi)), = problem.params.items()
    spec = problem.specs()[name]
    hard_only = problem.estimator.kind == "hard"
    with CompileClock() as clock:
        E, ev = _evaluator(problem, E, predictor, say, on_evaluation, figures)
        on_hard = hard_only or is_deterministic(E.sensor)
        domain = domain_check(E, getattr(E.predictor, "validation_rmse_m", None))
        if domain_note(domain):
            say("warning: " + domain_note(domain))
        say(f"{problem.sensor_kind}: stepped sweep and {'hard grid' if hard_only else 'continuous solve'} "
            f"of {name} over [{lo:g}, {hi:g}] {spec.unit}")
        result = _solve_line(ev, problem, on_hard)
        solve_counts = dict(ev.counts)
        say(f"{problem.sensor_kind}: r* = {result.r_star:.5g} {spec.unit}, "
            f"{'E_hard' if on_hard else 'E_ref'}(r*) = {result.E_hard_star:.4f} m")
        curves = report.curves(ev, E, result, lo, hi, problem.extra_curve_points, hard_only) if figures else None
        parts = report.breakdowns(ev, E, result, problem.miss_penalty_m2)
    figure_counts = {k: ev.counts[k] - solve_counts[k] for k in ev.counts}
    dense = None
    if problem.dense_check is not None:
        say(f"{problem.sensor_kind}: dense reference grid every {problem.dense_check:g} {spec.unit}")
        dense = report.dense_check(ev, result, lo, hi, problem.dense_check)
        result = dataclasses.replace(result, notes=(*result.notes, "dense check: " + dense["verdict"]))
    if domain_note(domain):
        result = dataclasses.replace(result, notes=(*result.notes, domain_note(domain)))
    answered = [(x[0], ev.e_hard(x[0])) for x in ev.hard_points()] if on_hard else \
        [(x[0], ev.e_reference(x[0])) for x in ev.reference_points()]
    answer = near_optimal(answered, lo, hi, result.r_star)
    out = Result(
        sensor=problem.sensor_kind, params=dict(problem.params), units={name: spec.unit},
        r_star={name: float(result.r_star)}, E_hard_star=ev.e_hard(result.r_star),
        E_soft_star=float(result.E_soft_star), solve=result,
        programs_run={"solve": solve_counts, "figures": figure_counts},
        wall_s={"compile": clock.compile_s, "run": clock.run_s, "programs_compiled": clock.compiled,
                "programs_lowered": clock.lowered},
        scenarios=tuple(E.scenario_names),
        config=_config(problem), curves=curves, dense_check=dense, near_optimal=answer["near_optimal"],
        flags=tuple(answer["flags"]), domain=domain, reference=report.reference_summary(ev, problem, result.r_star, on_hard),
        **parts)
    return out, E
