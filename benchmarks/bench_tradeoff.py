"""The speed/accuracy trade of the main job: each knob a user can turn, one at a time.

    python benchmarks/bench_tradeoff.py [--variants-ref 16] [--grid-step 1] [--quick]
        [--mc-samples 1,4,16,64] [--mc-cost-only K,...] [--taus 0.5,2,4] [--variant-counts 1,2,4]
        [--model PATH] [--scenarios sc01,...] [--variants 8] [--interval LO HI]
        [--compilation-cache] [--json PATH]

From the default of `python -m diffsense.optimise --param hfov --interval 30 180`
(configs/optimise/default.toml: radar, six scenarios x 8 variants, mean-field estimator, final
temperature multiplier 1, float64) one knob changes at a time: the estimator (Monte-Carlo with
K = 1, 4, 16, 64; --mc-cost-only times a K per soft evaluation without solving it; hard), the
final temperature multiplier (0.5, 2, 4; the continuation keeps its shape, as `--tau` does),
float32, and the variants per scenario (1, 2, 4). --interval measures another problem (e.g.
5 60, an interior optimum; the sweep's steps follow the interval). Each row runs the main
job's search: the stepped sweep and the continuous solve (for the hard estimator, the sweep and
an even hard grid in the best bracket, as diffsense.optimise does).

Error is measured against a reference: a dense hard grid (--grid-step, deg) over the interval on
--variants-ref variants per scenario. r*_ref is its best point and E_hard_ref its hard objective;
every row's r* is evaluated on it: dE_hard = E_hard_ref(r*) - E_hard_ref(r*_ref) [m] (negative
when r* beats every grid point).

Columns: compile s, JAX compilation (trace, lowering, backend; diffsense.report.CompileClock)
of building the row's problem and of its search; build s, the rest of building the problem
(scenes, ground-truth predictions); run s, the search without compilation; evaluations, the
objective programs the search ran (soft value-and-gradient and hard). Rows marked * reuse the
default's compiled problem (the temperature is a traced argument, and the hard estimator needs
only the hard program): a fresh process would compile as much as the default row. Seeds are
fixed (the config's seed 0): the same command gives the same r* and errors. Compilation is cold
(JAX's persistent cache off) unless --compilation-cache; --json writes every row, the reference
grid and the Pareto rows (notebook 02 reads it).
"""

from __future__ import annotations

import argparse
import dataclasses
import gc
import json
import os
import platform
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

KNOBS = ("default", "estimator", "temperature", "precision", "variants")
# Every soft evaluation with K samples runs the CS-LSTM K times (about 2 s per sample on the
# 2-core machine): the K = 64 solve alone takes about 20 min.
MC_SAMPLES = (1, 4, 16, 64)
MC_COST_ONLY: tuple[int, ...] = ()
TAUS = (0.5, 2.0, 4.0)
VARIANTS = (1, 2, 4)


@dataclasses.dataclass(frozen=True)
class Setting:
    """One row: a knob, its setting, and the problem it runs (`diffsense.Problem`, its solve
    settings included)."""

    knob: str
    label: str
    problem: object


@dataclasses.dataclass(frozen=True)
class Reference:
    """The dense hard grid on many variants: the yardstick of every row.

    Attributes:
        evaluator: the reference objective's `diffsense.solve.Evaluator` (its `e_hard` is E_hard_ref).
        dense: the grid search (r [deg], E_hard [m]).
        problem: the reference's `diffsense.Problem`.
        variants: variants per scenario [-]; grid_step: grid spacing [deg].
        compile_s, run_s: wall time of building the reference and of its grid [s].
    """

    evaluator: object
    dense: object
    problem: object
    variants: int
    grid_step: float
    compile_s: float
    run_s: float

    @property
    def r_star(self) -> float:
        return float(self.dense.r[self.dense.best_index])

    @property
    def E_star(self) -> float:
        return float(self.dense.E_hard[self.dense.best_index])


@dataclasses.dataclass(frozen=True)
class Row:
    """One measured setting; times in s, r in deg, E in m."""

    knob: str
    label: str
    shared: bool
    compile_s: float
    build_s: float
    run_s: float
    evaluations: int
    r_star: float
    E_hard: float  # E_hard(r*) on the row's own problem
    E_hard_ref: float  # E_hard_ref(r*)
    dr: float  # |r* - r*_ref|
    dE_hard: float  # E_hard_ref(r*) - E_hard_ref(r*_ref)


def default_problem(model: str | None = None, scenarios: Sequence[str] | None = None,
                    variants: int | None = None, interval: tuple[float, float] | None = None):
    """configs/optimise/default.toml as a `diffsense.Problem`, optionally with other weights,
    scenarios, variant count or interval of the parameter [its units]."""
    import diffsense as ds

    base = ds.Problem.from_toml(None)
    changes = {}
    if model:
        changes["predictor"] = model
    if scenarios:
        changes["scenarios"] = tuple(scenarios)
    if variants:
        changes["variants"] = variants
    if interval is not None:
        changes["params"] = {interval_name(base): (float(interval[0]), float(interval[1]))}
    return base.replace(**changes) if changes else base


def interval_name(problem) -> str:
    """The one free parameter of a problem."""
    (name,) = problem.params
    return name


def with_final_tau(solve_cfg, tau: float):
    """The continuation scaled so that its last level is `tau` (what `--tau` does)."""
    last = solve_cfg.tau_schedule[-1]
    return dataclasses.replace(solve_cfg, tau_schedule=tuple(t * tau / last for t in solve_cfg.tau_schedule))


def settings(problem, quick: bool = False, mc_samples: Sequence[int] = MC_SAMPLES,
             taus: Sequence[float] = TAUS, variants: Sequence[int] = VARIANTS) -> list[Setting]:
    """The default, then one knob changed at a time.

    `quick`: one setting per knob, none of which compiles a new estimator (the hard estimator,
    final tau 2, the other float type, 2 variants). Otherwise `mc_samples`, `taus` and
    `variants` are the Monte-Carlo K, final temperature multipliers and variants per scenario
    tried (besides the hard estimator and the other float type).
    """
    replace = dataclasses.replace
    p, s = problem, problem.solver.solve
    mc = () if quick else tuple(mc_samples)
    taus = (2.0,) if quick else tuple(taus)
    variants = (2,) if quick else tuple(variants)
    est = p.question.estimator
    rows = [Setting("default", f"{est.kind}, tau {s.tau_schedule[-1]:g}, "
                               f"{'float64' if p.prediction.float64 else 'float32'}, {p.traffic.variants} var", p)]
    for k in mc:
        rows.append(Setting("estimator", f"mc K={k}", p.replace(estimator=replace(est, kind="mc", samples=k))))
    rows.append(Setting("estimator", "hard", p.replace(estimator=replace(est, kind="hard"))))
    for tau in taus:
        rows.append(Setting("temperature", f"tau {tau:g}", p.replace(solve=with_final_tau(s, tau))))
    other = "float32" if p.prediction.float64 else "float64"
    rows.append(Setting("precision", other, p.replace(float64=not p.prediction.float64, solve=replace(s, dtype=other))))
    for n in variants:
        if n != p.traffic.variants:
            rows.append(Setting("variants", f"{n} var", p.replace(variants=n)))
    return rows


def objective_key(problem) -> tuple:
    """Problems with the same E(r), which compile to the same programs: the solve settings do
    not enter E, and the hard estimator runs only the hard program, which does not depend on
    the estimator's settings."""
    from diffsense.metrics import EstimatorConfig

    estimator = EstimatorConfig() if problem.question.estimator.kind == "hard" else problem.question.estimator
    predictor = problem.prediction.predictor if isinstance(problem.prediction.predictor, str) else id(problem.prediction.predictor)
    return (problem.sensor_kind, tuple(problem.traffic.scenarios), problem.traffic.variants, problem.seed, predictor,
            problem.prediction.fill, estimator, problem.traffic.prediction_stride_frames, problem.traffic.background_vehicles, problem.prediction.float64)


def interval_of(problem) -> tuple[float, float]:
    lo, hi = problem.params[interval_name(problem)]
    return float(lo), float(hi)


def reference(problem, predictor, variants: int, grid_step: float) -> Reference:
    """The dense hard grid over the problem's interval on `variants` variants per scenario."""
    import diffsense as ds
    from diffsense import report, solve
    from diffsense.metrics import EstimatorConfig

    estimator = EstimatorConfig() if problem.question.estimator.kind == "hard" else problem.question.estimator
    ref_problem = problem.replace(variants=variants, estimator=estimator)
    with report.CompileClock() as clock:
        ev = solve.Evaluator(ds.objective(ref_problem, predictor=predictor))
        dense = solve.dense_grid_search(ev.e_hard, interval_of(problem), grid_step)
    return Reference(evaluator=ev, dense=dense, problem=ref_problem, variants=variants, grid_step=grid_step,
                     compile_s=clock.compile_s, run_s=clock.run_s)


def measure(rows: Sequence[Setting], predictor, ref: Reference,
            progress: Callable[[str], None] = lambda _: None) -> list[Row]:
    """Run every setting's search (`diffsense.optimise` on the setting's problem, figures off),
    timed, and evaluate its r* on the reference."""
    import diffsense as ds
    from diffsense import report

    keys = [objective_key(s.problem) for s in rows]
    ref_key = objective_key(ref.problem)
    built = {ref_key: ref.evaluator.objective}  # a row on the reference's own problem reuses it
    out = []
    for i, (setting, key) in enumerate(zip(rows, keys)):
        progress(f"{setting.knob}: {setting.label}")
        shared = key in built
        compile_s = build_s = 0.0
        if not shared:
            with report.CompileClock() as clock:
                built[key] = ds.objective(setting.problem, predictor=predictor)
            compile_s, build_s = clock.compile_s, clock.run_s
        # optimise evaluates through a fresh evaluator: every row pays for its own evaluations.
        with report.CompileClock() as clock:
            result = ds.optimise(setting.problem, E=built[key], figures=False)
        evaluations = sum(result.programs_run["solve"].values())
        r_star = result.r_star[interval_name(setting.problem)]
        e_ref = ref.evaluator.e_hard(r_star)
        out.append(Row(
            knob=setting.knob, label=setting.label, shared=shared,
            compile_s=compile_s + clock.compile_s, build_s=build_s, run_s=clock.run_s,
            evaluations=evaluations, r_star=r_star, E_hard=result.E_hard_star, E_hard_ref=e_ref,
            dr=abs(r_star - ref.r_star), dE_hard=e_ref - ref.E_star,
        ))
        progress(f"  run {clock.run_s:.1f} s, {evaluations} evaluations, r* {r_star:.2f} deg, "
                 f"dE_hard {out[-1].dE_hard:+.4f} m")
        if key not in keys[i + 1:] and key != ref_key:
            del built[key]  # free its memory; no later row needs it
            gc.collect()
    return out


def evaluation_cost(problem, predictor, samples: Sequence[int]) -> list[tuple[str, float, float]]:
    """(label, compile s, s per soft value-and-gradient) of the Monte-Carlo estimator with each K,
    without a solve: for K too costly to solve (every soft evaluation runs the CS-LSTM K times)."""
    import diffsense as ds
    from diffsense import report, solve

    lo, hi = interval_of(problem)
    tau = problem.solver.solve.tau_schedule[-1]
    out = []
    for k in samples:
        est = dataclasses.replace(problem.question.estimator, kind="mc", samples=k)
        with report.CompileClock() as clock:
            ev = solve.Evaluator(ds.objective(problem.replace(estimator=est), predictor=predictor))
            ev.value_and_grad(0.5 * (lo + hi), tau)  # compiles
        t0 = time.perf_counter()
        ev.value_and_grad(0.5 * (lo + hi) + 1.0, tau)  # a new point: not memoised
        out.append((f"mc K={k}", clock.compile_s, time.perf_counter() - t0))
        del ev
        gc.collect()
    return out


def pareto(rows: Sequence[Row]) -> list[int]:
    """Indices of the rows no other row beats on both run s and dE_hard, fastest first."""
    front = [i for i, a in enumerate(rows)
             if not any((b.run_s <= a.run_s and b.dE_hard <= a.dE_hard)
                        and (b.run_s < a.run_s or b.dE_hard < a.dE_hard) for b in rows)]
    return sorted(front, key=lambda i: rows[i].run_s)


def table(rows: Sequence[Row], ref: Reference) -> str:
    """The printed table, with the reference's line and the Pareto-optimal rows marked."""
    front = set(pareto(rows))
    lines = [
        f"reference: dense hard grid every {ref.grid_step:g} deg on {ref.variants} variants per scenario "
        f"({ref.dense.evaluations} evaluations, compile {ref.compile_s:.1f} s, run {ref.run_s:.1f} s): "
        f"r*_ref = {ref.r_star:.2f} deg, E_hard_ref(r*_ref) = {ref.E_star:.4f} m",
        f"{'knob':<12} {'setting':<32} {'compile s':>9} {'build s':>8} {'run s':>7} {'evals':>6} "
        f"{'r* deg':>8} {'|r*-r*_ref|':>11} {'dE_hard m':>10} {'pareto':>6}",
    ]
    for i, r in enumerate(rows):
        compile_s = f"{r.compile_s:.1f}" + ("*" if r.shared else " ")
        build_s = "-" if r.shared else f"{r.build_s:.1f}"
        lines.append(
            f"{r.knob:<12} {r.label:<32} {compile_s:>9} {build_s:>8} {r.run_s:7.1f} {r.evaluations:>6} "
            f"{r.r_star:8.2f} {r.dr:11.2f} {r.dE_hard:+10.4f} {'yes' if i in front else '':>6}"
        )
    lines.append("* reuses the default's compiled problem; a fresh process compiles as much as the default row")
    return "\n".join(lines)


def to_json(problem, rows: Sequence[Row], ref: Reference, costs) -> dict:
    """Every number of the run, JSON-ready (what --json writes)."""
    lo, hi = interval_of(problem)
    return {
        "problem": {"sensor": problem.sensor_kind, "param": interval_name(problem), "interval": [lo, hi],
                    "scenarios": list(problem.traffic.scenarios), "variants": problem.traffic.variants},
        "reference": {"variants": ref.variants, "grid_step": ref.grid_step, "evaluations": ref.dense.evaluations,
                      "compile_s": ref.compile_s, "run_s": ref.run_s, "r_star": ref.r_star, "E_star": ref.E_star,
                      "r": [float(v) for v in ref.dense.r], "E_hard": [float(v) for v in ref.dense.E_hard]},
        "rows": [dataclasses.asdict(r) for r in rows],
        "pareto": pareto(rows),
        "cost_only": [{"label": label, "compile_s": c, "eval_s": e} for label, c, e in costs],
        "table": table(rows, ref),
    }


def _numbers(text: str, kind: type) -> tuple:
    return tuple(kind(x) for x in text.split(",") if x.strip())


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--variants-ref", type=int, default=16, help="variants per scenario of the reference")
    p.add_argument("--grid-step", type=float, default=1.0, help="reference grid spacing [deg]")
    p.add_argument("--quick", action="store_true", help="one setting per knob (no Monte-Carlo row)")
    p.add_argument("--mc-samples", default=",".join(map(str, MC_SAMPLES)),
                   help="comma-separated Monte-Carlo K of the estimator knob (solved)")
    p.add_argument("--mc-cost-only", default=",".join(map(str, MC_COST_ONLY)),
                   help="comma-separated K whose cost per soft evaluation is measured, not solved")
    p.add_argument("--taus", default=",".join(f"{t:g}" for t in TAUS),
                   help="comma-separated final temperature multipliers tried besides the default's")
    p.add_argument("--variant-counts", default=",".join(map(str, VARIANTS)),
                   help="comma-separated variants per scenario tried besides the default's")
    p.add_argument("--model", default=None, help="predictor weights (default: the shipped ones)")
    p.add_argument("--scenarios", default=None, help="comma-separated scenarios (default: the config's six)")
    p.add_argument("--variants", type=int, default=None, help="variants per scenario of the default (config: 8)")
    p.add_argument("--interval", type=float, nargs=2, default=None, metavar=("LO", "HI"),
                   help="the parameter's interval (default: the config's, HFOV 30 180 deg)")
    p.add_argument("--compilation-cache", action="store_true",
                   help="use JAX's persistent compilation cache (default: off, compile times are cold)")
    p.add_argument("--json", type=Path, default=None, help="also write every number of the run to this file")
    args = p.parse_args()

    import diffsense as ds
    from diffsense import cli

    cli.setup_jax(float64=True, compilation_cache=args.compilation_cache)
    import jax

    print(f"jax {jax.__version__} on {jax.default_backend()}, {os.cpu_count()} CPU cores, "
          f"{platform.processor() or platform.machine()}")
    t0 = time.perf_counter()

    def progress(message: str) -> None:
        print(f"[{time.perf_counter() - t0:7.1f} s] {message}", file=sys.stderr, flush=True)

    scenarios = [x.strip() for x in args.scenarios.split(",") if x.strip()] if args.scenarios else None
    problem = default_problem(args.model, scenarios, args.variants, args.interval)
    predictor = ds.predictors.load_predictor(args.model)
    progress(f"reference: {args.variants_ref} variants, grid every {args.grid_step:g} deg")
    ref = reference(problem, predictor, args.variants_ref, args.grid_step)
    rows = measure(settings(problem, quick=args.quick, mc_samples=_numbers(args.mc_samples, int),
                            taus=_numbers(args.taus, float), variants=_numbers(args.variant_counts, int)),
                   predictor, ref, progress)
    cost_only = _numbers(args.mc_cost_only, int)
    if cost_only:
        progress(f"cost per evaluation of mc K={args.mc_cost_only}")
    costs = evaluation_cost(problem, predictor, cost_only)
    print(table(rows, ref))
    if costs:
        print("\nnot solved (cost per soft evaluation only; a solve runs the evaluations column's count):")
        print(f"{'estimator':<12} {'compile s':>9} {'s per soft value-and-gradient':>30}")
        for label, compile_s, eval_s in costs:
            print(f"{label:<12} {compile_s:9.1f} {eval_s:30.1f}")
    if args.json:
        args.json.write_text(json.dumps(to_json(problem, rows, ref, costs), indent=1) + "\n")
    print(f"total wall {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
