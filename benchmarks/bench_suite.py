"""Sensor-suite design: the gradient box solve against CMA-ES, optuna TPE and random search.

    nice -n 19 python benchmarks/bench_suite.py [--quick] [--dims 4,8,16] [--seeds 5]
        [--budget-per-dim 25] [--cost-weight 0.002] [--scenarios sc01,...] [--variants 2]
        [--stride 8] [--laws] [--draws 32] [--judge-draws 128] [--out out/bench_suite]

Problem: J(r) = E(r) + lambda * cost(r) of a fused radar + camera suite (`sensors._fusion.Suite`,
`metrics._cost`, configs/costs.toml) with the shipped CS-LSTM, over d = 4, 8 or 16 of its
parameters in the boxes of PARAMS (d = 16: a suite of two radars and two cameras, eight
parameters each pair, the second pair mounted like the first: two sensors give 9 parameters).
Every method is judged by the HARD J of the points it evaluates:

    gradient    solve._box.box_solve: Halton sample of 2 d + 2 points (hard), BFGS on the soft J
                with temperature continuation (4, 2, 1) from up to 4 of the best points while
                the budget lasts, every level's answer checked hard
    CMA-ES      the `cma` package on the unit cube (sigma0 0.3, default population)
    TPE         optuna's TPESampler
    random      uniform in the box

Budgets are equal in value evaluations: a hard evaluation costs 1, a soft value-and-gradient
costs c = (its wall time) / (a hard evaluation's), both measured here after compilation (fastest
of 7 at random points). The hard program computes E alone (`e_hard` below; the Evaluator's hard
program also computes per-scenario RMSE curves, which would overcharge the baselines). Every run
starts with empty memos (nothing is reused across runs). The table gives, per d, the best J any
run found, each method's median final J over the seeds, and the evaluations each needs to come
within 1 % of that best (median over seeds; runs that never do count as never), and the soft J
(final temperature) at each method's best point: whether the surrogate the gradient descends ranks
the answers as the hard J does. Below it, J_hard and J_soft along the segment from the gradient's
best answer to the best point any run found. Needs the
`suite-bench` extra (cma, optuna). Writes summary.json and best_vs_evaluations.png under --out.

--laws puts each member under its probabilistic detection law (LAWS: a Swerling I radar, a
confidence camera). Every method is then judged by E_ref, the mean of the hard objective over
--draws detection draws with common random numbers, in place of the hard E; the gradient
descends relaxed-reference (the default estimator for several parameters under such laws), whose
relaxed draws are E_ref's own. A best found on E_ref can owe part of its value to its draws (the
more so the lower a method gets on them), so each run's best point is judged again on
--judge-draws draws independent of E_ref's (`Objective.reference`'s indices from --draws on): the
"judged" column.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

from diffsense.metrics import EstimatorConfig, load_costs, make_cost, make_objective, simulate_scenes  # noqa: E402
from diffsense.predictors import load_predictor  # noqa: E402
from diffsense.sensors import Camera, Radar, Suite  # noqa: E402
import equinox as eqx  # noqa: E402
from diffsense.solve import BoxConfig, BoxFunctions, box_solve  # noqa: E402
from diffsense.tracks import prediction_frames  # noqa: E402

PAIR = {  # one radar + camera pair's eight parameters and their boxes
    "radar.hfov_deg": (20.0, 120.0), "radar.range_m": (30.0, 200.0),
    "camera.hfov_deg": (30.0, 150.0), "camera.width_px": (640.0, 3840.0),
    "radar.tx_power_dbm": (0.0, 20.0), "radar.noise_figure_db": (3.0, 12.0),
    "camera.range_m": (30.0, 200.0), "camera.baseline_m": (0.05, 0.5),
}
PARAMS = {4: dict(list(PAIR.items())[:4]), 8: PAIR,
          16: PAIR | {k.replace("radar.", "radar2.").replace("camera.", "camera2."): v for k, v in PAIR.items()}}
METHODS = ("gradient", "CMA-ES", "TPE", "random")
ROOT = Path(__file__).resolve().parents[1]
LAWS = {"radar": ROOT / "configs/sensors/laws/radar_swerling1.toml",
        "camera": ROOT / "configs/sensors/laws/camera_confidence.toml"}
LEVELS = (4.0, 2.0, 1.0)
MAX_STEPS = 30


def build(d: int, args, predictor):
    """E (the objective over PARAMS[d]) and the jitted cost value-and-gradient."""
    if args.laws:
        radar, camera = Radar.from_toml(LAWS["radar"]), Camera.from_toml(LAWS["camera"])
    else:
        radar, camera = Radar.from_toml(), Camera.from_toml()
    suite = Suite((radar, camera)) if d <= 8 else Suite((radar, camera, radar, camera),
                                                         names=("radar", "camera", "radar2", "camera2"))
    names = tuple(PARAMS[d])
    scene_key, noise_key = jax.random.split(jax.random.PRNGKey(0))
    scenes, index, scenario_names, weather = simulate_scenes(
        args.scenarios, args.variants, scene_key, spec=predictor.spec, sensors=[suite],
        stride_frames=args.stride, dtype=jnp.float64)
    frames = prediction_frames(scenes.num_frames, args.stride, predictor.spec, scenes.dt_s)
    E = make_objective(scenes, index, frames, suite, predictor, names=names, key=noise_key,
                       scenario_names=scenario_names, weather=weather,
                       estimator=EstimatorConfig(reference_draws=args.draws))
    cost = make_cost(load_costs(), suite)
    vg = jax.jit(jax.value_and_grad(lambda v: cost(dict(zip(names, v)))))

    def cost_fn(x):
        v, g = vg(jnp.asarray(x, jnp.float64))
        return float(v), np.asarray(g)

    return E, cost_fn


@eqx.filter_jit
def _e_hard(E, x):
    return jnp.sqrt(E.hard(E.point(x)).e2)  # the rest of HardEvaluation is dead code here


@eqx.filter_jit
def _e2_vg(E, x, tau):
    return jax.value_and_grad(lambda v: E.e2(E.point(v), tau))(x)


@eqx.filter_jit
def _e_ref(E, x, draws):
    return E.reference(E.point(x), draws).e


def probabilistic(E) -> bool:
    """True when E's detections are drawn (the members' laws are probabilistic)."""
    return E.estimator_kind != "mean-field"


def e_hard(E, x) -> float:
    """The E every method is judged by [m] at x (values of E.names): the hard E, or E_ref under
    probabilistic laws."""
    x = jnp.asarray(x, jnp.float64)
    return float(_e_ref(E, x, None) if probabilistic(E) else _e_hard(E, x))


def e_judged(E, x, first: int, count: int) -> float:
    """E_ref [m] at x on `count` draws from index `first` on (independent of E_ref's own when
    `first` is its number of draws)."""
    return float(_e_ref(E, jnp.asarray(x, jnp.float64), jnp.arange(first, first + count)))


def e2_soft(E, x, tau) -> tuple[float, np.ndarray]:
    """Soft E^2 [m^2] and its gradient at x."""
    v, g = _e2_vg(E, jnp.asarray(x, jnp.float64), jnp.asarray(tau, jnp.float64))
    return float(v), np.asarray(g)


def measure_c(E, bounds: np.ndarray) -> tuple[float, float, float]:
    """(c, t_hard [s], t_value_and_grad [s]): the fastest of 7 at random points each, after
    compiling (on a shared machine the minimum is the program's own cost; medians drift with load)."""
    rng = np.random.default_rng(123)
    points = bounds[:, 0] + (bounds[:, 1] - bounds[:, 0]) * rng.random((8, len(bounds)))
    e_hard(E, points[0]), e2_soft(E, points[0], 1.0)  # compile
    th, tv = [], []
    for x in points[1:]:
        t = time.perf_counter(); e_hard(E, x); th.append(time.perf_counter() - t)  # noqa: E702
        t = time.perf_counter(); e2_soft(E, x, 1.0); tv.append(time.perf_counter() - t)  # noqa: E702
    return float(min(tv) / min(th)), float(min(th)), float(min(tv))


def run_gradient(E, cost_fn, bounds, lam, budget, c, seed):
    """The box solve within `budget` evaluations: [(evaluations spent, J_hard)] per hard evaluation."""
    d = len(bounds)
    fns = BoxFunctions(E.names, lambda x, tau: e2_soft(E, x, tau), lambda x: e_hard(E, x), cost_fn)
    samples, starts = 2 * d + 2, 4
    soft = max(0, int((budget - samples - starts * len(LEVELS)) / c) - starts - 1)
    # Each start runs until its levels converge (ftol) or MAX_STEPS; later starts get what the
    # earlier ones left of the budget.
    config = BoxConfig(samples=samples, starts=starts, tau_schedule=LEVELS, max_soft=soft, max_steps=MAX_STEPS,
                       cost_weight=lam, seed=seed)
    result = box_solve(fns, dict(zip(E.names, map(tuple, bounds))), config)
    spent, trace, best = 0.0, [], (math.inf, None)
    for e in result.history:
        spent += c if e.kind == "soft" else 1.0
        if e.kind == "hard":
            trace.append((spent, e.value + lam * cost_fn(e.x)[0]))
            best = min(best, (trace[-1][1], e.x), key=lambda t: t[0])
    return trace, {"x_star": result.x_star, "on_bound": result.on_bound, "counts": result.counts,
                   "x_best": [float(v) for v in best[1]]}


def _hard_j(E, cost_fn, lam, lo, width):
    """J_hard on the unit cube; j.best holds [J, x] of the lowest point it evaluated."""
    def j(u):
        x = lo + width * np.clip(u, 0.0, 1.0)
        value = e_hard(E, x) + lam * cost_fn(x)[0]
        if value < j.best[0]:
            j.best = [value, x.tolist()]
        return value

    j.best = [math.inf, None]
    return j


def run_cma(E, cost_fn, bounds, lam, budget, seed):
    import cma

    lo, width = bounds[:, 0], bounds[:, 1] - bounds[:, 0]
    j, trace = _hard_j(E, cost_fn, lam, lo, width), []
    es = cma.CMAEvolutionStrategy(len(lo) * [0.5], 0.3, {"bounds": [0, 1], "seed": seed + 1, "verbose": -9})
    while len(trace) < budget and not es.stop():
        xs = es.ask()
        values = [j(np.asarray(x)) for x in xs[: budget - len(trace)]]
        trace += [(len(trace) + i + 1.0, v) for i, v in enumerate(values)]
        if len(values) < len(xs):
            break
        es.tell(xs, values)
    return trace, {"x_best": j.best[1]}


def run_tpe(E, cost_fn, bounds, lam, budget, seed):
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    lo, width = bounds[:, 0], bounds[:, 1] - bounds[:, 0]
    j, trace = _hard_j(E, cost_fn, lam, lo, width), []

    def objective(trial):
        u = np.array([trial.suggest_float(f"u{i}", 0.0, 1.0) for i in range(len(lo))])
        trace.append((len(trace) + 1.0, j(u)))
        return trace[-1][1]

    optuna.create_study(sampler=optuna.samplers.TPESampler(seed=seed)).optimize(objective, n_trials=budget)
    return trace, {"x_best": j.best[1]}


def run_random(E, cost_fn, bounds, lam, budget, seed):
    lo, width = bounds[:, 0], bounds[:, 1] - bounds[:, 0]
    j = _hard_j(E, cost_fn, lam, lo, width)
    trace = [(i + 1.0, j(u)) for i, u in enumerate(np.random.default_rng(seed).random((budget, len(lo))))]
    return trace, {"x_best": j.best[1]}


def to_within(trace, target: float) -> float:
    """Evaluations spent when the best J so far first reaches `target` (inf if never)."""
    best = math.inf
    for spent, value in trace:
        best = min(best, value)
        if best <= target:
            return spent
    return math.inf


def best_curve(trace, grid):
    """Best J so far at each number of evaluations in `grid` (nan before the first)."""
    out, best, i = [], math.nan, 0
    for g in grid:
        while i < len(trace) and trace[i][0] <= g:
            best = trace[i][1] if math.isnan(best) else min(best, trace[i][1])
            i += 1
        out.append(best)
    return out


def compare(d, args, predictor):
    E, cost_fn = build(d, args, predictor)
    bounds = np.array(list(PARAMS[d].values()))
    c, t_hard, t_vg = measure_c(E, bounds)
    budget = args.budget_per_dim * d
    judge = "E_ref" if probabilistic(E) else "hard E"
    print(f"d = {d}: judged on {judge}, the gradient descends {E.estimator_kind}; a value-and-gradient "
          f"costs c = {c:.2f} evaluations of {judge} ({t_vg * 1e3:.1f} / {t_hard * 1e3:.1f} ms); budget {budget}",
          flush=True)
    runs = {m: [] for m in METHODS}
    for seed in range(args.seeds):
        for method in METHODS:
            t = time.perf_counter()
            if method == "gradient":
                trace, extra = run_gradient(E, cost_fn, bounds, args.cost_weight, budget, c, seed)
            else:
                fn = {"CMA-ES": run_cma, "TPE": run_tpe, "random": run_random}[method]
                trace, extra = fn(E, cost_fn, bounds, args.cost_weight, budget, seed)
            runs[method].append({"seed": seed, "trace": trace, "wall_s": time.perf_counter() - t} | extra)
    best = min(v for rs in runs.values() for r in rs for _, v in r["trace"])
    target = best + 0.01 * abs(best)
    rows = {}
    for method, rs in runs.items():
        reach = [to_within(r["trace"], target) for r in rs]
        rows[method] = {"final_J_median": float(np.median([min(v for _, v in r["trace"]) for r in rs])),
                        "evaluations_to_1pct_median": float(np.median(reach)),
                        "reached": int(sum(math.isfinite(x) for x in reach)),
                        "evaluations_to_1pct": [x if math.isfinite(x) else None for x in reach]}
    soft_vs_hard(E, cost_fn, args.cost_weight, runs, rows)
    if probabilistic(E):
        judged(E, cost_fn, args, runs, rows)
    baseline = min(rows[m]["evaluations_to_1pct_median"] for m in METHODS[1:])
    grad = rows["gradient"]["evaluations_to_1pct_median"]
    # No baseline's median run got within 1 % inside the budget: the ratio is below grad / budget.
    ratio = grad / baseline if math.isfinite(baseline) else (grad / budget if math.isfinite(grad) else math.nan)
    bound = "=" if math.isfinite(baseline) or not math.isfinite(grad) else "<"
    return {"d": d, "names": list(PARAMS[d]), "bounds": bounds.tolist(), "c": c, "t_hard_s": t_hard,
            "t_value_and_grad_s": t_vg, "budget": budget, "best_J": best, "rows": rows,
            "gradient_over_best_baseline": ratio if math.isfinite(ratio) else None, "ratio_is": bound, "runs": runs,
            "line": line_scan(E, cost_fn, args.cost_weight, runs)}


def soft_j(E, cost_fn, lam, x, tau=LEVELS[-1]) -> float:
    """The soft J the gradient solve descends at its final temperature [m]."""
    return math.sqrt(e2_soft(E, x, tau)[0]) + lam * cost_fn(np.asarray(x))[0]


def soft_vs_hard(E, cost_fn, lam, runs, rows):
    """Each run's best point scored by the soft J too: does the surrogate rank the answers as J_hard does?"""
    for method, rs in runs.items():
        for r in rs:
            r["J_soft_at_best"] = soft_j(E, cost_fn, lam, r["x_best"])
        rows[method]["J_soft_at_best_median"] = float(np.median([r["J_soft_at_best"] for r in rs]))


def judged(E, cost_fn, args, runs, rows):
    """Each run's best point judged on draws independent of E_ref's own (module doc)."""
    for method, rs in runs.items():
        for r in rs:
            x = np.asarray(r["x_best"])
            r["J_judged_at_best"] = (e_judged(E, x, args.draws, args.judge_draws)
                                     + args.cost_weight * cost_fn(x)[0])
        rows[method]["J_judged_at_best_median"] = float(np.median([r["J_judged_at_best"] for r in rs]))


def line_scan(E, cost_fn, lam, runs, points=11):
    """J_hard and J_soft on the segment from the gradient's best answer (t = 0) to the best point any
    run found (t = 1): where the two disagree, descending the soft J leads away from the hard optimum."""
    best_of = lambda r: min(v for _, v in r["trace"])  # noqa: E731
    start = min(runs["gradient"], key=best_of)["x_best"]
    end = min((r for rs in runs.values() for r in rs), key=best_of)["x_best"]
    out = []
    for t in np.linspace(0.0, 1.0, points):
        x = np.asarray(start) + t * (np.asarray(end) - np.asarray(start))
        out.append({"t": float(t), "J_hard": e_hard(E, x) + lam * cost_fn(x)[0], "J_soft": soft_j(E, cost_fn, lam, x)})
    return out


def report(results, args):
    print(f"\nJ = E + {args.cost_weight:g} * cost [m]; evaluations to within 1 % of the best J any run found "
          f"(median over {args.seeds} seeds; reached = runs that got there)")
    if args.laws:
        print(f"J is judged on E_ref ({args.draws} draws); 'judged' is the best point's J on {args.judge_draws} "
              "independent draws")
    print(f"{'d':>3} {'method':<9} {'median final J':>15} {'soft J there':>13} {'evals to 1 %':>13} {'reached':>8}"
          + (f" {'judged':>9}" if args.laws else ""))
    for res in results:
        for method, row in res["rows"].items():
            e = row["evaluations_to_1pct_median"]
            extra = f" {row['J_judged_at_best_median']:>9.4f}" if args.laws else ""
            print(f"{res['d']:>3} {method:<9} {row['final_J_median']:>15.4f} {row['J_soft_at_best_median']:>13.4f} "
                  f"{(f'{e:.0f}' if math.isfinite(e) else 'never'):>13} {row['reached']:>5}/{args.seeds}{extra}")
        ratio = res["gradient_over_best_baseline"]
        text = "undefined (no median run got within 1 %)" if ratio is None else f"{res['ratio_is']} {ratio:.2f}"
        print(f"    best J {res['best_J']:.4f}; gradient / best baseline evaluations {text} "
              "(target <= 0.2 at d = 8, 16)")
        print("    from the gradient's best answer (t 0) to the best point found (t 1): t J_hard J_soft")
        for p in res["line"]:
            print(f"      {p['t']:.1f} {p['J_hard']:9.4f} {p['J_soft']:9.4f}")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(5 * len(results), 4), squeeze=False)
    for ax, res in zip(axes[0], results):
        grid = np.arange(1, res["budget"] + 1)
        for method, rs in res["runs"].items():
            curves = np.array([best_curve(r["trace"], grid) for r in rs])
            ax.plot(grid, np.nanmedian(curves, axis=0), label=method)
            ax.fill_between(grid, np.nanmin(curves, axis=0), np.nanmax(curves, axis=0), alpha=0.15)
        ax.set(title=f"d = {res['d']}", xlabel="evaluations (value-and-gradient = c)", ylabel="best J so far [m]",
               xscale="log")
        ax.legend()
    fig.tight_layout()
    args.out.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out / "best_vs_evaluations.png", dpi=120)
    meta = {"machine": platform.platform(), "processor": platform.processor(), "jax": jax.__version__,
            "devices": [str(x) for x in jax.devices()], "args": {k: str(v) for k, v in vars(args).items()}}
    (args.out / "summary.json").write_text(json.dumps({"meta": meta, "results": results}, indent=1))
    print(f"wrote {args.out / 'summary.json'} and {args.out / 'best_vs_evaluations.png'}")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="d 4 and 8, 2 seeds, sc01 x 1 variant, stride 20, budget 25 d")
    p.add_argument("--dims", default="4,8,16")
    p.add_argument("--seeds", type=int, default=5)
    p.add_argument("--budget-per-dim", type=int, default=25, help="evaluations per parameter")
    p.add_argument("--cost-weight", type=float, default=0.002, help="lambda [m per EUR]")
    p.add_argument("--scenarios", default="sc01,sc02,sc03,sc04,sc05,sc06")
    p.add_argument("--variants", type=int, default=2)
    p.add_argument("--stride", type=int, default=8, help="prediction stride [frames]")
    p.add_argument("--laws", action="store_true",
                   help="each member under its probabilistic detection law; J judged on E_ref (module doc)")
    p.add_argument("--draws", type=int, default=32, help="detection draws of E_ref (with --laws)")
    p.add_argument("--judge-draws", type=int, default=128,
                   help="independent draws each run's best point is judged on again (with --laws)")
    p.add_argument("--out", type=Path, default=Path("out/bench_suite"))
    args = p.parse_args(argv)
    if args.quick:
        args.dims, args.seeds, args.budget_per_dim = "4,8", 2, 25
        args.scenarios, args.variants, args.stride = "sc01", 1, 20
    args.scenarios = [s for s in args.scenarios.split(",") if s]
    predictor = load_predictor(None)
    results = [compare(int(d), args, predictor) for d in args.dims.split(",")]
    report(results, args)


if __name__ == "__main__":
    main()
