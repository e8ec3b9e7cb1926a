"""The grid-search baseline: the continuous solve against grids, bounded Brent and a Bayesian optimiser.

    nice -n 19 python benchmarks/bench_baseline.py [--variants 8] [--scenarios sc01,...]
        [--problems SENSOR:PARAM:LO:HI:STEP ...] [--brent-maxiter 100] [--trials 40] [--json PATH]

On one objective E(r) (the main job's: `diffsense.objective` of the default problem with the
sensor and parameter of --problems), every method below searches the same interval and is
judged by the hard E of its answer:

    continuous solve        diffsense.solve.solve: the paper's sweep, then optimistix refinement
    ... + reserved polish   the same with SolveConfig(reserve_polish=True) (not yet the default)
    paper/stepped grid      the sweep's steps alone, hard (the paper's 30, 60, ..., 180 deg on HFOV 30-180)
    dense grid (hard)       diffsense.solve.dense_grid_search every STEP (see --problems)
    Brent on E_hard/E_soft  scipy.optimize.minimize_scalar(method="bounded"), derivative-free
    Bayesian (optuna TPE)   optional extra `baseline` (skipped with a line when not installed)

Evaluations are the objective's compiled programs that actually ran (the counters of a
`diffsense.solve.Evaluator`, memo misses only): hard = hard E, soft = soft E^2 value only, grad =
soft E^2 value and gradient (the evaluator serves every soft request of the solve, sweep values
included, with the value-and-gradient program). The objective's programs are compiled once
first (the solve's own root-find program compiles in its first call: JAX's measured compile time
is taken off its wall time); every method gets a fresh evaluator, so no method reuses another's
evaluations. E_hard(r*) of an answer the method did not evaluate itself is computed for the
table and not counted. --json writes every comparison with each method's evaluation trace
(notebook 03 reads it).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import time
from collections.abc import Callable
from pathlib import Path

import equinox as eqx
import jax
import numpy as np

KINDS = ("hard", "soft", "grad")
# The main job's problem with the 0.5-deg dense grid, and a second one whose optimum is
# interior with the shipped weights: narrow radar fields of view (on 30-180 deg E_hard grows with
# the HFOV, so the best value is the lower bound; radar range 30-200 m and camera HFOV 30-180 deg
# were tried too: a plateau to the upper bound, and the lower bound).
PROBLEMS = ("radar:hfov_deg:30:180:0.5", "radar:hfov_deg:5:60:0.5")
# The evaluator's counter of each kind: the value-only program is the benchmark's own.
_COUNTER = {"hard": "hard", "grad": "soft"}


@dataclasses.dataclass(frozen=True)
class Setting:
    """One comparison: the problem and the size knobs of the methods.

    Attributes:
        sensor, param: the free parameter (`param` as `diffsense.Problem` takes it: "hfov_deg", "hfov").
        interval: (lo, hi) in the parameter's units.
        dense_step: spacing of the dense hard grid, parameter units.
        brent_maxiter: iteration cap of bounded Brent (it stops earlier at xatol).
        trials: evaluations of the Bayesian optimiser.
        xtol_rel: Brent's xatol relative to the interval width (the solve's default, 1e-3).
        seed: the Bayesian optimiser's seed.
    """

    sensor: str
    param: str
    interval: tuple[float, float]
    dense_step: float = 0.5
    brent_maxiter: int = 100
    trials: int = 40
    xtol_rel: float = 1e-3
    seed: int = 0

    @property
    def label(self) -> str:
        return f"{self.sensor} {self.param} {self.interval[0]:g}-{self.interval[1]:g}"


@dataclasses.dataclass(frozen=True)
class Evaluation:
    """One program run: kind (hard, soft, grad), r, the value (E [m] hard, E^2 [m^2] soft) and
    its wall time [s]."""

    kind: str
    r: float
    value: float
    wall_s: float


@dataclasses.dataclass(frozen=True)
class MethodRun:
    """One method's search: its answer, E_hard of the answer [m], program runs and wall time."""

    name: str
    r_star: float
    E_hard_star: float
    counts: dict[str, int]
    wall_s: float
    trace: tuple[Evaluation, ...]
    note: str = ""

    @property
    def evaluations(self) -> int:
        return sum(self.counts.values())


@dataclasses.dataclass(frozen=True)
class Comparison:
    setting: Setting
    unit: str
    runs: tuple[MethodRun, ...]
    dense: object  # diffsense.solve.DenseGrid (the dense-grid row's search)
    skipped: tuple[str, ...]
    cost_s: dict[str, float]  # mean wall time of one program run of each kind

    @property
    def best(self) -> float:
        """The smallest E_hard seen anywhere in the comparison [m]."""
        seen = [e.value for run in self.runs for e in run.trace if e.kind == "hard"]
        return min(seen + [run.E_hard_star for run in self.runs])


@eqx.filter_jit
def _e2_value(E, x, tau):
    # The objective is an argument, not a closure, so XLA does not fold its data in as constants.
    return E.e2(E.point(x), tau)


class Recorder:
    """Per method, a fresh `diffsense.solve.Evaluator` of the objective with counting wrappers on
    its evaluation methods, and a value-only soft program. The solver callbacks of
    `Evaluator.solver_fns` look the methods up at call time, so the solve's evaluations are
    recorded too; the evaluator's own counters cross-check. `scorer` evaluates off the books."""

    def __init__(self, E):
        from diffsense.solve import Evaluator

        self.E = E
        self.ev = Evaluator(E)
        self.scorer = Evaluator(E)
        self.trace: list[Evaluation] = []

    def _wrap(self, kind: str, method: Callable) -> Callable:
        def counted(r, *args):
            before, t0 = self.ev.counts[_COUNTER[kind]], time.perf_counter()
            out = method(r, *args)
            if self.ev.counts[_COUNTER[kind]] > before:  # a memo hit runs no program
                value = out[0] if isinstance(out, tuple) else out
                self.trace.append(Evaluation(kind, float(r), float(value), time.perf_counter() - t0))
            return out

        return counted

    def __enter__(self) -> Recorder:
        from diffsense.solve import Evaluator

        self.trace = []
        self.ev = Evaluator(self.E)  # no method reuses another's evaluations
        self.ev.value_and_grad = self._wrap("grad", self.ev.value_and_grad)
        self.ev.e_hard = self._wrap("hard", self.ev.e_hard)
        return self

    def __exit__(self, *exc) -> None:
        for kind, counter in _COUNTER.items():
            ran = self.ev.counts[counter]
            if exc[0] is None and ran != self.counts()[kind]:
                raise RuntimeError(f"{kind}: the evaluator ran {ran} programs, the recorder saw {self.counts()[kind]}")

    def e2_value(self, r: float, tau: float = 1.0) -> float:
        """Soft E^2 [m^2] at r without its gradient (what a derivative-free method needs)."""
        t0 = time.perf_counter()
        dtype = self.E.dtype
        value = float(_e2_value(self.E, jax.numpy.asarray(r, dtype), jax.numpy.asarray(tau, dtype)))
        self.trace.append(Evaluation("soft", float(r), value, time.perf_counter() - t0))
        return value

    def counts(self) -> dict[str, int]:
        return {k: sum(e.kind == k for e in self.trace) for k in KINDS}

    def run(self, name: str, search: Callable[[], float], note: str = "") -> MethodRun:
        """Time `search() -> r*` on a fresh evaluator; E_hard(r*) afterwards, not counted."""
        with self:
            t0 = time.perf_counter()
            r_star = float(search())
            wall = time.perf_counter() - t0
            trace = tuple(self.trace)
        e_star = next((e.value for e in trace if e.kind == "hard" and e.r == r_star), None)
        if e_star is None:
            e_star = self.scorer.e_hard(r_star)
        counts = {k: sum(e.kind == k for e in trace) for k in KINDS}
        return MethodRun(name, r_star, float(e_star), counts, wall, trace, note)


def build(setting: Setting, variants: int, scenarios: tuple[str, ...] | None = None, predictor=None):
    """The main job's problem for `setting` and its objective (shipped weights unless a
    predictor is given): (`diffsense.Problem`, E)."""
    import diffsense as ds

    fields = {"sensor": setting.sensor, "params": {setting.param: setting.interval}, "variants": variants}
    if scenarios:
        fields["scenarios"] = tuple(scenarios)
    problem = ds.Problem.from_toml(None, **fields)
    return problem, ds.objective(problem, predictor=predictor)


def _brent(f: Callable[[float], float], setting: Setting) -> float:
    from scipy.optimize import minimize_scalar

    lo, hi = setting.interval
    res = minimize_scalar(f, bounds=(lo, hi), method="bounded",
                          options={"xatol": setting.xtol_rel * (hi - lo), "maxiter": setting.brent_maxiter})
    return float(res.x)


def _optuna(e_hard: Callable[[float], float], setting: Setting) -> float:
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(sampler=optuna.samplers.TPESampler(seed=setting.seed))
    study.optimize(lambda trial: e_hard(trial.suggest_float("r", *setting.interval)), n_trials=setting.trials)
    return float(study.best_params["r"])


def optuna_available() -> bool:
    try:
        import optuna  # noqa: F401
    except ImportError:
        return False
    return True


def compare(problem, E, setting: Setting) -> Comparison:
    """Run every method on the objective E of `problem` (see the module docstring)."""
    from diffsense import report
    from diffsense.solve import (
        PAPER_HFOV_STEPS_DEG,
        DenseGrid,
        SolveConfig,
        default_steps,
        dense_grid_search,
        solve,
    )

    lo, hi = setting.interval
    rec = Recorder(E)
    # Compile the objective's programs (hard, value and gradient, value only) once.
    rec.scorer.e_hard(lo), rec.scorer.value_and_grad(lo), rec.e2_value(lo)
    import scipy.optimize  # noqa: F401  (its first import takes a second: not a method's cost)

    def e_hard(r):  # the current method's evaluator, looked up at call time
        return rec.ev.e_hard(r)

    runs, skipped = [], []
    result = {}

    def continuous(config):
        def search():
            # The solve's own root-find program compiles in its first call: JAX's compile time
            # is measured (CompileClock) and taken off the solve's wall time below.
            with report.CompileClock() as clock:
                result["solve"] = solve(*rec.ev.solver_fns(), (lo, hi), config=config)
            result["compile_s"] = clock.compile_s
            return result["solve"].r_star

        return search

    # The first row is the shipped solve (the verdict is about it); the second keeps the hard
    # polish's evaluations back from the continuation.
    solves = (("continuous solve (sweep + optimistix)", SolveConfig()),
              ("continuous solve + reserved polish (reserve_polish)", SolveConfig(reserve_polish=True)))
    for name, config in solves:
        run = rec.run(name, continuous(config))
        res = result["solve"]
        runs.append(dataclasses.replace(run, wall_s=run.wall_s - result["compile_s"],
                                        note="; ".join(res.notes) + ("; on a bound" if res.on_bound else "")))

    steps = default_steps(lo, hi)

    def grid():
        e = [e_hard(float(r)) for r in steps]
        return float(steps[int(np.argmin(e))])

    paper = setting.param.startswith("hfov") and tuple(steps) == PAPER_HFOV_STEPS_DEG
    kind = "paper" if paper else "stepped"
    runs.append(rec.run(f"{kind} grid, {len(steps)} steps (hard)", grid))
    dense: dict[str, DenseGrid] = {}

    def dense_search():
        dense["grid"] = dense_grid_search(e_hard, (lo, hi), setting.dense_step)
        g = dense["grid"]
        return float(g.r[g.best_index])

    runs.append(rec.run(f"dense grid, step {setting.dense_step:g} (hard)", dense_search))
    runs.append(rec.run("bounded Brent on E_hard (scipy)", lambda: _brent(e_hard, setting)))
    runs.append(rec.run("bounded Brent on E_soft (scipy)", lambda: _brent(rec.e2_value, setting)))
    if optuna_available():
        runs.append(rec.run(f"Bayesian, optuna TPE, {setting.trials} trials (hard)",
                            lambda: _optuna(e_hard, setting)))
    else:
        skipped.append("Bayesian (optuna TPE): skipped: optuna is not installed (pip install -e '.[baseline]')")
    every = [e for run in runs for e in run.trace]
    cost = {k: float(np.median([e.wall_s for e in every if e.kind == k])) for k in KINDS
            if any(e.kind == k for e in every)}
    (name,) = problem.params
    unit = E.sensor.spec(name).unit
    return Comparison(setting, unit, tuple(runs), dense["grid"], tuple(skipped), cost)


def table(comp: Comparison) -> str:
    """The comparison as aligned text (diffsense.report.format_table)."""
    from diffsense.report import format_table

    best = comp.best
    headers = ["method", "evals hard/soft/grad", "wall s", f"r* {comp.unit}", "E_hard(r*) m", "E_hard - best m"]
    rows = [[run.name, " / ".join(str(run.counts[k]) for k in KINDS), f"{run.wall_s:.1f}",
             f"{run.r_star:.2f}", f"{run.E_hard_star:.4f}", f"{run.E_hard_star - best:+.4f}"] for run in comp.runs]
    lines = [format_table(headers, rows)]
    lines += [f"  {s}" for s in comp.skipped]
    lines.append("median wall of one program run: " + ", ".join(f"{k} {v:.2f} s" for k, v in comp.cost_s.items()))
    notes = [f"  {run.name}: {run.note}" for run in comp.runs if run.note]
    return "\n".join(lines + (["notes:"] + notes if notes else []))


def verdict(comp: Comparison) -> list[str]:
    """The continuous solve against each other method: evaluations, wall time and E_hard, one line
    each (what the issue asks: fewer evaluations at equal or better E_hard, or where not)."""
    solve, others = comp.runs[0], comp.runs[1:]
    lines = []
    for run in others:
        d = solve.E_hard_star - run.E_hard_star
        quality = "equal E_hard" if abs(d) < 5e-5 else f"{'better' if d < 0 else 'WORSE'} E_hard by {abs(d):.4f} m"
        fewer = "fewer" if solve.evaluations < run.evaluations else "NOT fewer"
        lines.append(f"vs {run.name}: {solve.evaluations} against {run.evaluations} evaluations ({fewer}), "
                     f"{solve.wall_s:.1f} against {run.wall_s:.1f} s wall, {quality}")
    return lines


def best_so_far(e_hard: Callable[[float], float], run: MethodRun) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(evaluations used, cumulative wall s, best E_hard among the points evaluated so far [m]).

    A point evaluated only softly gets its E_hard computed here, off the method's books (for the
    convergence figure; these evaluations are not counted against the method).
    """
    hard = {e.r: e.value for e in run.trace if e.kind == "hard"}
    best, out = np.inf, []
    for e in run.trace:
        if e.r not in hard:
            hard[e.r] = e_hard(e.r)
        best = min(best, hard[e.r])
        out.append(best)
    n = np.arange(1, len(run.trace) + 1)
    return n, np.cumsum([e.wall_s for e in run.trace]), np.asarray(out)


def convergence(E, comp: Comparison) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """`best_so_far` of every method of `comp`, soft-only points evaluated hard off the books."""
    from diffsense.solve import Evaluator

    e_hard = Evaluator(E).e_hard
    return [best_so_far(e_hard, run) for run in comp.runs]


def to_json(comp: Comparison, curves, scenarios: int, variants: int) -> dict:
    """One comparison, every evaluation included, JSON-ready (what --json writes)."""
    d = comp.dense
    return {
        "setting": dataclasses.asdict(comp.setting), "label": comp.setting.label, "unit": comp.unit,
        "scenarios": scenarios, "variants": variants, "best": comp.best, "skipped": list(comp.skipped),
        "cost_s": comp.cost_s, "table": table(comp), "verdict": verdict(comp),
        "dense": {"r": [float(v) for v in d.r], "E_hard": [float(v) for v in d.E_hard],
                  "best_index": int(d.best_index), "evaluations": int(d.evaluations)},
        "runs": [{"name": run.name, "r_star": run.r_star, "E_hard_star": run.E_hard_star, "counts": run.counts,
                  "evaluations": run.evaluations, "wall_s": run.wall_s, "note": run.note,
                  "trace": [dataclasses.asdict(e) for e in run.trace],
                  "best_so_far": {"n": n.tolist(), "wall_s": wall.tolist(), "E_hard": best.tolist()}}
                 for run, (n, wall, best) in zip(comp.runs, curves)],
    }


def _parse_problem(text: str) -> tuple[str, str, tuple[float, float], float]:
    try:
        sensor, param, lo, hi, step = text.split(":")
        return sensor, param, (float(lo), float(hi)), float(step)
    except ValueError:
        raise SystemExit(f"error: --problems entries are SENSOR:PARAM:LO:HI:STEP, got {text!r}") from None


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--variants", type=int, default=8, help="variants per scenario")
    p.add_argument("--scenarios", default="", help="comma-separated (default: the paper's six)")
    p.add_argument("--problems", nargs="+", default=list(PROBLEMS),
                   help="SENSOR:PARAM:LO:HI:STEP each, STEP the dense grid's spacing in the parameter's units "
                   "(default: %(default)s: the main job's radar HFOV and narrow radar HFOVs)")
    p.add_argument("--brent-maxiter", type=int, default=100)
    p.add_argument("--trials", type=int, default=40, help="Bayesian optimiser evaluations")
    p.add_argument("--json", type=Path, default=None,
                   help="also write every comparison, with each method's evaluations, to this file")
    args = p.parse_args()

    import diffsense as ds
    from diffsense import cli

    cli.setup_jax(float64=True, compilation_cache=True)
    print(f"jax {jax.__version__} on {jax.default_backend()}, {os.cpu_count()} CPU cores, "
          f"{platform.processor() or platform.machine()}; variants per scenario {args.variants}")
    predictor = ds.predictors.load_predictor(None)
    scenarios = tuple(s for s in args.scenarios.split(",") if s) or None
    built = {}  # one E(r) per sensor parameter, whatever its interval
    out = []
    for text in args.problems:
        sensor, param, interval, step = _parse_problem(text)
        setting = Setting(sensor, param, interval, dense_step=step,
                          brent_maxiter=args.brent_maxiter, trials=args.trials)
        if (sensor, param) not in built:
            built[sensor, param] = build(setting, args.variants, scenarios, predictor)
        problem, E = built[sensor, param]
        comp = compare(problem, E, setting)
        n = len(E.scenario_names) * args.variants
        print(f"\n{setting.label} ({n} scenes)")
        print(table(comp))
        print("\ncontinuous solve " + "\n                 ".join(verdict(comp)))
        if args.json:
            out.append(to_json(comp, convergence(E, comp), len(E.scenario_names), args.variants))
    if args.json:
        args.json.write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()
