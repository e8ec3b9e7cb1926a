"""Design at 8-32 parameters: the design solve against CMA-ES, TPE, a GP sampler and random search.

    nice -n 19 python benchmarks/bench_design.py [--suites radar_camera_d8,...] [--seeds 5]
        [--budget-per-dim 25] [--variants 1] [--stride 20] [--draws 32] [--gradient-draws 8] [--judge-draws 64]
        [--batch 8] [--methods design,CMA-ES,TPE,GP,random] [--gp-seeds N] [--json-dir benchmarks/results]
        [--render docs/suite.md]

Problem: each shipped suite file (configs/suites/NAME.toml) under its members' physical laws
(Swerling I radars, confidence cameras), the default scenarios at --variants variants and one
prediction every --stride frames, J = E_ref + lambda * cost with the file's lambda. E_ref is the
mean of the hard objective over --draws detection draws (common random numbers).

Methods, all on the same compiled programs of one `diffsense.solve.Evaluator`, fresh memos per run:

    design   diffsense's box solve as `diffsense.optimise` runs it under a probabilistic law:
             a Halton sample of 8 d + 8 points screened on E_ref's first 4 draws (batched),
             the best 4 evaluated on E_ref, BFGS on relaxed-reference over the first
             --gradient-draws draws with temperature continuation (4, 2, 1) from them while the
             budget lasts, its iterate every 3 steps and every level's answer judged on E_ref
    CMA-ES   the `cma` package on the unit cube (sigma0 0.3, default population), each
             population one batched program (vmap over r)
    TPE      optuna's TPESampler, one point at a time
    GP       optuna's GPSampler (needs torch), one point at a time
    random   uniform in the box, --batch points per batched program

Budgets are equal in value-evaluation cost: one E_ref at one point costs 1; a value-and-gradient,
a point of a batched program and a screened point cost their measured times over its (medians
of interleaved calls after compiling). A batched program is charged whole, padding included.

Judged on fresh data: each run's incumbent (its best J so far) is judged, every time it changes,
on the judging seed's problem (`diffsense.study.judging_objective`: other scene variants, noise
and draws), E_ref on --judge-draws draws + lambda * cost. Per method and seed the JSON holds the
evaluations spent until the judged incumbent is within 1 % of the best judged value any run
found (null if never) and the judged value of its final answer. Writes
`design_d{D}.json` per suite, `design_d{D}.png` (best judged J against evaluations and against
wall time) beside it; --render replaces the table between `<!-- design-table -->` and
`<!-- /design-table -->` in the given Markdown file with the one rendered from every
design_d*.json in --json-dir, and copies their figures into the file's img/ folder.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import time
from pathlib import Path

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import diffsense as ds  # noqa: E402
from diffsense.metrics import EstimatorConfig, load_costs, make_cost  # noqa: E402
from diffsense.solve import BoxConfig, BoxFunctions, Evaluator, box_solve  # noqa: E402
from diffsense.study import judge_seed, judging_objective  # noqa: E402
from _markdown import replace_block  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SUITES = "radar_camera_d8"
METHODS = ("design", "CMA-ES", "TPE", "GP", "random")
SCREEN_DRAWS, STARTS, LEVELS = 4, 4, (4.0, 2.0, 1.0)


class Ledger:
    """What a run has spent [value evaluations] and its incumbents (spent, wall s, J, x)."""

    def __init__(self, budget: float):
        self.budget, self.spent, self.best, self.t0 = budget, 0.0, math.inf, time.perf_counter()
        self.incumbents: list[tuple[float, float, float, list[float]]] = []

    def left(self) -> float:
        return self.budget - self.spent

    def offer(self, x, j: float) -> None:
        if j < self.best:
            self.best = j
            self.incumbents.append((self.spent, time.perf_counter() - self.t0, float(j), [float(v) for v in x]))


def measure_costs(ev: Evaluator, lo, hi, batch: int, repeats: int = 5) -> dict[str, float]:
    """Seconds of each kind of evaluation (medians, calls interleaved, distinct random points)
    and their costs in values: vg (value-and-gradient), batch (a point of a full batched
    program), screen (a screened point)."""
    rng = np.random.default_rng(12345)
    point = lambda: lo + (hi - lo) * rng.random(len(lo))  # noqa: E731
    block = lambda: lo + (hi - lo) * rng.random((batch, len(lo)))  # noqa: E731
    calls = {"value": lambda: ev.reference(point()), "vg": lambda: ev.value_and_grad(point(), 1.0),
             "batch": lambda: ev.reference_batch(block(), None, batch),
             "screen": lambda: ev.reference_batch(block(), SCREEN_DRAWS, batch)}
    times = {k: [] for k in calls}
    for _ in range(repeats + 1):  # the first round compiles
        for k, fn in calls.items():
            t = time.perf_counter()
            fn()
            times[k].append(time.perf_counter() - t)
    s = {k: float(np.median(v[1:])) for k, v in times.items()}
    s["batch"] /= batch
    s["screen"] /= batch
    return {"seconds": s, "vg": s["vg"] / s["value"], "batch": s["batch"] / s["value"],
            "screen": s["screen"] / s["value"]}


def run_design(ctx, seed: int, ledger: Ledger) -> None:
    ev, costs, d = Evaluator(ctx["E"]), ctx["costs"], ctx["d"]
    fns = BoxFunctions.from_evaluator(ev, cost=ctx["cost_model"], e_answer=ev.e_reference,
                                      screen_draws=SCREEN_DRAWS, batch=ctx["batch"])
    screen = 8 * d + 8
    price = {"soft": costs["vg"], "hard": 1.0, "screen": costs["screen"]}

    def listen(event) -> None:
        ledger.spent += price[event.kind]
        if event.kind == "hard":
            ledger.offer(event.x, event.value + ctx["lam"] * fns.cost(event.x)[0])

    fns.listener = listen
    levels, every = ctx["levels"], BoxConfig().check_every
    # the screen, the starts' and each level's hard checks, then per BFGS step a value-and-gradient
    # and a share of the iterate's check
    fixed = screen * costs["screen"] + STARTS * (1 + len(levels))
    if fixed + STARTS * costs["vg"] > ledger.budget:  # not even one step of each start: no equal budget
        raise SystemExit(f"error: a budget of {ledger.budget:g} values is below the design solve's fixed cost at "
                         f"d = {d} ({fixed + STARTS * costs['vg']:.0f}: its screen, starts, checks and one step "
                         f"each); raise --budget-per-dim")
    soft = max(0, int((ledger.budget - fixed) / (costs["vg"] + 1.0 / every)) - STARTS)
    config = BoxConfig(screen_points=screen, screen_draws=SCREEN_DRAWS, starts=STARTS, tau_schedule=levels,
                       max_soft=soft, max_steps=30, cost_weight=ctx["lam"], seed=seed, **ctx.get("box", {}))
    box_solve(fns, ctx["bounds"], config)


def _j_batch(ctx, ev: Evaluator, us: np.ndarray, ledger: Ledger) -> np.ndarray:
    """J of unit-cube points in batched programs, charged per program (padding included)."""
    xs = ctx["lo"] + ctx["width"] * np.clip(us, 0.0, 1.0)
    e = ev.reference_batch(xs, None, ctx["batch"])
    ledger.spent += math.ceil(len(xs) / ctx["batch"]) * ctx["batch"] * ctx["costs"]["batch"]
    j = e + ctx["lam"] * np.array([ctx["cost"](x) for x in xs])
    for x, v in zip(xs, j):
        ledger.offer(x, v)
    return j


def _affordable(ctx, ledger: Ledger, n: int) -> int:
    per_program = ctx["batch"] * ctx["costs"]["batch"]
    programs = int(ledger.left() // per_program + 1e-9)
    return max(0, min(n, programs * ctx["batch"]))


def run_cma(ctx, seed: int, ledger: Ledger) -> None:
    import cma

    ev = Evaluator(ctx["E"])
    es = cma.CMAEvolutionStrategy(ctx["d"] * [0.5], 0.3, {"bounds": [0, 1], "seed": seed + 1, "verbose": -9})
    while not es.stop():
        us = es.ask()
        n = _affordable(ctx, ledger, len(us))
        if n == 0:
            break
        j = _j_batch(ctx, ev, np.array(us[:n]), ledger)
        if n < len(us):
            break
        es.tell(us, list(j))


def run_random(ctx, seed: int, ledger: Ledger) -> None:
    ev, rng = Evaluator(ctx["E"]), np.random.default_rng(seed)
    while (n := _affordable(ctx, ledger, ctx["batch"])) > 0:
        _j_batch(ctx, ev, rng.random((n, ctx["d"])), ledger)


def run_optuna(sampler_name: str):
    def run(ctx, seed: int, ledger: Ledger) -> None:
        import optuna

        optuna.logging.set_verbosity(optuna.logging.WARNING)
        ev = Evaluator(ctx["E"])
        sampler = (optuna.samplers.TPESampler(seed=seed) if sampler_name == "TPE"
                   else optuna.samplers.GPSampler(seed=seed))

        def objective(trial):
            u = np.array([trial.suggest_float(f"u{i}", 0.0, 1.0) for i in range(ctx["d"])])
            x = ctx["lo"] + ctx["width"] * u
            ledger.spent += 1.0
            j = ev.e_reference(x) + ctx["lam"] * ctx["cost"](x)
            ledger.offer(x, j)
            return j

        optuna.create_study(sampler=sampler).optimize(objective, n_trials=int(ledger.budget))

    return run


RUNNERS = {"design": run_design, "CMA-ES": run_cma, "TPE": run_optuna("TPE"), "GP": run_optuna("GP"),
           "random": run_random}


def judge_runs(ctx, runs: dict, judge_draws: int) -> None:
    """Each incumbent's J on the judging seed's problem (`judged` beside each), batched."""
    judge_ev = Evaluator(ctx["judge"])
    points = sorted({tuple(inc[3]) for rs in runs.values() for r in rs for inc in r["incumbents"]})
    e = judge_ev.reference_batch(np.array(points), judge_draws, ctx["batch"])
    judged = {p: float(v) + ctx["lam"] * ctx["cost"](np.array(p)) for p, v in zip(points, e)}
    for rs in runs.values():
        for r in rs:
            r["judged"] = [judged[tuple(inc[3])] for inc in r["incumbents"]]


def first_within(r: dict, target: float, column: int) -> float | None:
    """Spent evaluations (column 0) or wall seconds (column 1) when the judged incumbent first
    comes within the target."""
    hits = [inc[column] for inc, j in zip(r["incumbents"], r["judged"]) if j <= target]
    return hits[0] if hits else None


def context(suite: str, args, predictor) -> dict:
    problem = ds.Problem.from_suite(ROOT / "configs" / "suites" / f"{suite}.toml", variants=args.variants,
                                    prediction_stride_frames=args.stride,
                                    estimator=EstimatorConfig(reference_draws=args.draws,
                                                              gradient_draws=args.gradient_draws))
    E = ds.objective(problem, predictor=predictor)
    lo = np.array([b[0] for b in problem.params.values()])
    hi = np.array([b[1] for b in problem.params.values()])
    model = make_cost(load_costs(problem.question.costs), E.sensor)
    cost_vg = jax.jit(jax.value_and_grad(lambda v: model({n: v[i] for i, n in enumerate(E.names)})))
    ctx = {"problem": problem, "E": E, "judge": judging_objective(problem, E), "d": len(lo), "lo": lo, "hi": hi,
           "width": hi - lo, "bounds": dict(problem.params), "lam": problem.question.cost_weight,
           "cost_model": model, "cost": lambda x: float(cost_vg(np.asarray(x, np.float64))[0]), "batch": args.batch,
           "levels": tuple(float(t) for t in args.levels.split(","))}
    ctx["costs"] = measure_costs(Evaluator(E), lo, hi, args.batch)
    return ctx


def compare(suite: str, args, predictor) -> dict:
    ctx = context(suite, args, predictor)
    d, costs = ctx["d"], ctx["costs"]
    budget = args.budget_per_dim * d
    print(f"{suite}: d = {d}, estimator {ctx['E'].estimator_kind}, budget {budget} values; one value "
          f"{costs['seconds']['value'] * 1e3:.0f} ms, a value-and-gradient {costs['vg']:.2f} values, a batched point "
          f"{costs['batch']:.2f}, a screened point {costs['screen']:.2f}", flush=True)
    runs = {m: [] for m in args.methods if not (m == "GP" and args.gp_seeds == 0)}
    for seed in range(args.seeds):
        for method in args.methods:
            if method == "GP" and args.gp_seeds is not None and seed >= args.gp_seeds:
                continue  # its suggestions' own cost grows with the trials: fewer seeds where asked
            ledger = Ledger(budget)
            RUNNERS[method](ctx, seed, ledger)
            runs[method].append({"seed": seed, "spent": ledger.spent, "wall_s": time.perf_counter() - ledger.t0,
                                 "incumbents": ledger.incumbents})
            print(f"  seed {seed} {method:<7} best J {ledger.best:8.4f} m after {ledger.spent:6.1f} values, "
                  f"{runs[method][-1]['wall_s']:6.1f} s", flush=True)
    judge_runs(ctx, runs, args.judge_draws)
    best = min(j for rs in runs.values() for r in rs for j in r["judged"])
    target = 1.01 * best
    methods = {}
    for method, rs in runs.items():
        methods[method] = {
            "evals_to_within_1pct": [first_within(r, target, 0) for r in rs],
            "wall_to_within_1pct_s": [first_within(r, target, 1) for r in rs],
            "best_judged": [r["judged"][-1] for r in rs],
            "best_optimised": [r["incumbents"][-1][2] for r in rs],
            "spent": [r["spent"] for r in rs], "wall_s": [r["wall_s"] for r in rs]}
    return {"d": d, "suite": suite, "names": list(ctx["E"].names), "bounds": ctx["bounds"], "budget": budget,
            "costs": costs, "best_judged_any": best, "target": target, "methods": methods, "runs": runs,
            "problem": {"variants": args.variants, "stride_frames": args.stride, "draws": args.draws,
                        "judge_draws": args.judge_draws, "judge_seed": judge_seed(ctx["problem"].seed), "cost_weight": ctx["lam"], "scenarios": list(ctx["E"].scenario_names)}}


def _median_evals(values: list) -> float:
    """Median over seeds, a run that never got there counted as infinite."""
    return float(np.median([math.inf if v is None else v for v in values]))


def table(results: list[dict]) -> list[str]:
    """The Markdown table of every result: per d and method, evaluations to within 1 % of the best
    judged J (median over seeds, and how many seeds got there), median judged J, worst seed's."""
    lines = ["| d | method | evaluations to within 1 % (median) | seeds there | judged J median [m] | "
             "judged J worst [m] | worst / best judged | wall per run [s] (median) |",
             "|---|---|---|---|---|---|---|---|"]
    for res in sorted(results, key=lambda r: r["d"]):
        for method, row in res["methods"].items():
            e = _median_evals(row["evals_to_within_1pct"])
            reached = sum(v is not None for v in row["evals_to_within_1pct"])
            worst = max(row["best_judged"])
            lines.append(f"| {res['d']} | {method} | {f'{e:.0f}' if math.isfinite(e) else 'never'} | "
                         f"{reached}/{len(row['best_judged'])} | {np.median(row['best_judged']):.3f} | {worst:.3f} | "
                         f"{worst / res['best_judged_any']:.3f} | {np.median(row['wall_s']):.0f} |")
    return lines


def verdict(res: dict) -> str:
    """The issue's target in words: the design solve's median evaluations against the best
    baseline's (<= 1/2 at d = 8, <= 1/5 above), and its worst seed within 5 % of the best."""
    rows = res["methods"]
    if "design" not in rows:
        return ""
    design = _median_evals(rows["design"]["evals_to_within_1pct"])
    base = min((_median_evals(r["evals_to_within_1pct"]) for m, r in rows.items() if m != "design"), default=math.inf)
    goal = 0.5 if res["d"] <= 8 else 0.2
    if math.isfinite(base):
        ratio = f"{design / base:.2f}"
    else:  # no baseline's median run got within 1 %: the ratio is below design / budget
        ratio = f"< {design / res['budget']:.2f}" if math.isfinite(design) else "undefined"
    worst = max(rows["design"]["best_judged"]) / res["best_judged_any"]
    return (f"d = {res['d']}: design / best baseline evaluations {ratio} (target <= {goal:g}); design's worst seed "
            f"{100 * (worst - 1):.1f} % above the best judged J (target <= 5 %)")


def plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for column, ax, label in ((0, axes[0], "evaluations (value cost)"), (1, axes[1], "wall time [s]")):
        for method, rs in res["runs"].items():
            end = max(r["spent"] if column == 0 else r["wall_s"] for r in rs)
            grid = np.linspace(0.0, end, 200)
            curves = []
            for r in rs:
                xs = np.array([inc[column] for inc in r["incumbents"]])
                idx = np.searchsorted(xs, grid, side="right") - 1
                judged = np.array(r["judged"])
                curves.append(np.where(idx >= 0, judged[np.maximum(idx, 0)], np.nan))
            ax.plot(grid, np.nanmedian(np.array(curves), axis=0), label=method)
        ax.axhline(res["target"], color="k", lw=0.8, ls=":", label="within 1 % of best")
        ax.set(xlabel=label, ylabel="judged J of the incumbent [m] (median over seeds)", yscale="log",
               title=f"{res['suite']} (d = {res['d']})")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def render(markdown: Path, json_dir: Path) -> None:
    results = [json.loads(p.read_text()) for p in sorted(json_dir.glob("design_d*.json"))]
    replace_block(markdown, "design-table", "\n".join(table(results) + [""] + [f"- {verdict(r)}" for r in results]))
    img = markdown.parent / "img"
    for figure in sorted(json_dir.glob("design_d*.png")):  # the page's figures beside it
        img.mkdir(exist_ok=True)
        (img / figure.name).write_bytes(figure.read_bytes())
    print(f"rendered {len(results)} results and their figures into {markdown} and {img}")


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--suites", default=SUITES, help="comma-separated suite names (configs/suites/)")
    p.add_argument("--seeds", type=int, default=5)
    p.add_argument("--budget-per-dim", type=int, default=25, help="value evaluations per parameter")
    p.add_argument("--variants", type=int, default=1)
    p.add_argument("--stride", type=int, default=20, help="prediction stride [frames]")
    p.add_argument("--draws", type=int, default=32, help="detection draws of E_ref")
    p.add_argument("--gradient-draws", type=int, default=EstimatorConfig().gradient_draws,
                   help="draws the design solve's gradient is taken on (EstimatorConfig.gradient_draws)")
    p.add_argument("--judge-draws", type=int, default=64, help="draws of the judging seed's E_ref")
    p.add_argument("--batch", type=int, default=8, help="points per batched program")
    p.add_argument("--methods", default=",".join(METHODS))
    p.add_argument("--gp-seeds", type=int, default=None, help="run the GP sampler on the first N seeds only")
    p.add_argument("--levels", default=",".join(f"{t:g}" for t in LEVELS),
                   help="the design solve's temperature multipliers, largest first")
    p.add_argument("--json-dir", type=Path, default=ROOT / "benchmarks" / "results")
    p.add_argument("--render", type=Path, default=None, help="Markdown file whose design table is re-rendered")
    args = p.parse_args(argv)
    args.methods = [m for m in args.methods.split(",") if m]
    unknown = sorted(set(args.methods) - set(METHODS))
    if unknown:
        raise SystemExit(f"error: unknown method {unknown[0]} (known: {', '.join(METHODS)})")
    if args.suites:
        predictor = ds.predictors.load_predictor(None)
        for suite in args.suites.split(","):
            load = os.getloadavg()
            res = compare(suite, args, predictor)
            res["meta"] = {"machine": platform.platform(), "jax": jax.__version__, "load_before": load,
                           "load_after": os.getloadavg(), "args": {k: str(v) for k, v in vars(args).items()}}
            print("\n".join(table([res])) + "\n" + verdict(res))
            args.json_dir.mkdir(parents=True, exist_ok=True)
            path = args.json_dir / f"design_d{res['d']}.json"
            path.write_text(json.dumps(res, indent=1) + "\n")
            plot(res, path.with_suffix(".png"))
            print(f"wrote {path} and {path.with_suffix('.png')}", flush=True)
    if args.render:
        render(args.render, args.json_dir)


if __name__ == "__main__":
    main()
