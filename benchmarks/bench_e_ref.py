"""Benchmark: one evaluation of the main job's objective, E_ref, at the default problem's size,
against the floor its predictor passes set at the machine's best float32 matmul rate.

    python benchmarks/bench_e_ref.py [--repeats 6] [--dtypes auto,bfloat16]
        [--json benchmarks/results/e_ref_pipeline.json] [--render docs/scaling.md] [--render-only]

The default problem (`diffsense.Problem.from_toml()`: radar HFOV, 6 scenarios x 8 variants,
Swerling I, K = 32 reference draws) built once per predictor dtype (`predictor_dtype`: "auto" is
the float32 CS-LSTM, "bfloat16" its LSTM products on bfloat16 operands). Timed, compiled, at a
new HFOV each round so that nothing is memoised, the dtypes alternating (the order reversed every
other round), medians of --repeats:
- value: E_ref, `E(r, mode="reference")`, the value Brent's search runs on (K predictor passes);
- value+grad: the soft objective's value and gradient as the solver computes them
  (`diffsense.metrics.value_and_grad`: forward mode for one parameter), under the default
  estimator for one parameter (straight-through: E_ref's value, the gradient of the first
  `gradient_draws` relaxed draws): K passes for the value, and for each gradient draw one pass
  carrying its tangent.
The floor is the predictor's forward GFLOP (`_roofline.forward_gflop` at the pipeline's batch and
its 4 candidate neighbours per target) times the passes, at the best float32 matmul rate measured
in the same run (`_roofline.matmul_rates`); the value+grad floor counts a tangent pass as two
forward passes' products. E_ref(30 deg) of each dtype is printed beside its times.
`--render` replaces the `<!-- e-ref-table -->` block of a Markdown file.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from pathlib import Path

import jax
from _markdown import replace_block
from _roofline import forward_gflop, matmul_rates

import diffsense as ds
from diffsense import cli
from diffsense.metrics import value_and_grad

ROOT = Path(__file__).resolve().parents[1]
JSON = ROOT / "benchmarks" / "results" / "e_ref_pipeline.json"
NEIGHBOURS = 4  # the default problem's candidate neighbours per target (bench_predict prints it)


def _programs(E):
    value = jax.jit(lambda h: E({"hfov_deg": h}, mode="reference"))
    vg = jax.jit(lambda h: value_and_grad(lambda r: E(r))({"hfov_deg": h}))
    return {"value": value, "value+grad": vg}


def measure(dtypes: list[str], repeats: int) -> dict:
    cli.setup_jax(float64=True, compilation_cache=False)
    load0 = os.getloadavg()[0]
    problem = ds.Problem.from_toml()
    objectives = {d: ds.objective(problem.replace(predictor_dtype=d)) for d in dtypes}
    E0 = next(iter(objectives.values()))
    draws, grad_draws = E0.estimator.reference_draws, min(E0.estimator.gradient_draws, E0.estimator.reference_draws)
    batch = int(E0.data.gt_pred.shape[0] * E0.data.gt_pred.shape[1])
    programs = {d: _programs(E) for d, E in objectives.items()}
    e_ref_30 = {d: float(p["value"](30.0)) for d, p in programs.items()}  # compiles the value
    for p in programs.values():
        jax.block_until_ready(p["value+grad"](30.0))
    times = {d: {op: [] for op in ("value", "value+grad")} for d in dtypes}
    for i in range(repeats):
        h = 31.0 + 1.7 * i
        for d in (dtypes if i % 2 == 0 else dtypes[::-1]):
            for op, fn in programs[d].items():
                t0 = time.perf_counter()
                jax.block_until_ready(fn(h))
                times[d][op].append(time.perf_counter() - t0)
    rates = matmul_rates(batch, NEIGHBOURS)
    best = max(r["xla"] for r in rates.values())
    gflop = forward_gflop(batch, NEIGHBOURS)
    passes = {"value": draws, "value+grad": draws + 2 * grad_draws}
    rows = [{"dtype": d, "op": op, "median_s": statistics.median(t), "times_s": t, "passes": passes[op],
             "floor_s": passes[op] * gflop / best, "E_ref_30_m": e_ref_30[d]}
            for d in dtypes for op, t in times[d].items()]
    return {"batch": batch, "neighbours": NEIGHBOURS, "draws": draws, "gradient_draws": grad_draws,
            "forward_gflop": gflop, "best_gflop_s": best, "repeats": repeats, "rows": rows,
            "load": [load0, os.getloadavg()[0]],
            "meta": {"machine": platform.platform(), "cpus": os.cpu_count(), "jax": jax.__version__}}


def table(res: dict) -> str:
    lines = ["| predictor dtype | evaluation | median [s] | predictor passes | floor at the best matmul rate [s] | "
             "of the floor | E_ref(30 deg) [m] |", "|---|---|---|---|---|---|---|"]
    for r in res["rows"]:
        lines.append(f"| {r['dtype']} | {r['op']} | {r['median_s']:.2f} | {r['passes']} | {r['floor_s']:.2f} | "
                     f"{r['median_s'] / r['floor_s']:.1f}x | {r['E_ref_30_m']:.4f} |")
    return "\n".join(lines) + (
        f"\n\nB = {res['batch']} targets, {res['neighbours']} candidate neighbours each, K = {res['draws']} "
        f"reference draws, {res['gradient_draws']} gradient draws; one forward pass {res['forward_gflop']:.2f} GFLOP; "
        f"best float32 matmul rate {res['best_gflop_s']:.0f} GFLOP/s; medians of {res['repeats']}, the dtypes "
        f"alternating; load average {res['load'][0]:.1f} before, {res['load'][1]:.1f} after, on "
        f"{res['meta']['cpus']} cores (jax {res['meta']['jax']}). Measured with `python benchmarks/bench_e_ref.py`.")


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--repeats", type=int, default=6)
    p.add_argument("--dtypes", default="auto,bfloat16", help="predictor dtypes, comma-separated")
    p.add_argument("--json", type=Path, default=JSON)
    p.add_argument("--render", type=Path, default=None)
    p.add_argument("--render-only", action="store_true", help="render the stored JSON, measure nothing")
    args = p.parse_args(argv)
    if args.render_only:
        res = json.loads(args.json.read_text())
    else:
        dtypes = [d for d in args.dtypes.split(",") if d]
        if not dtypes or args.repeats < 1:
            raise SystemExit("error: --dtypes needs at least one dtype and --repeats at least 1")
        res = measure(dtypes, args.repeats)
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(res, indent=1) + "\n")
    print(table(res))
    if args.render:
        replace_block(args.render, "e-ref-table", table(res))


if __name__ == "__main__":
    main()
