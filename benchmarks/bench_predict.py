"""Benchmark: CS-LSTM forward and input-gradient time, JAX (this project) vs the PyTorch reference.

    python benchmarks/bench_predict.py [--repeats 30] [--batch B[,B...]] [--neighbours 12]
                                       [--checkpoint PATH] [--pause-ms 20] [--json PATH]
                                       [--render docs/scaling.md] [--render-only]

The default batch is the pipeline's own: the targets one evaluation of the default problem's E(r)
predicts (`diffsense.Problem.from_toml()`: its scenarios x variants x prediction instants, the
instants counted from each scenario's duration and the prediction stride without building a
scene; printed with where it came from). `--batch 128,5760` (any list) measures other batches in
the same run. B targets with N neighbours each (distinct random grid slots), float32, CPU. JAX runs the compact
path (`predict_mean`: only the N neighbours are encoded) under plain jax.jit; the PyTorch side is
a re-implementation of the reference highwayNet.forward in evaluation mode (masked_scatter_ into
the grid, one decode per manoeuvre) with the same weights (`_torch_reference.py`). Rows:
- forward: the predicted mean. Manoeuvre variant: the most probable manoeuvre; JAX decodes that
  one alone, the reference decodes all 6 and picks one (the torch column is its forward).
- all 6 modes: every manoeuvre's trajectory and the class probabilities, like the reference's
  forward (the same torch call as the row above).
- input gradient: d(sum of the predicted means)/d(inputs): JAX w.r.t. the target and neighbour
  histories and the occupancy weights, PyTorch w.r.t. the histories with its parameters frozen
  (so neither side forms weight gradients).
- bf16 products: the same two with the LSTMs' products on bfloat16 operands into float32 sums
  (`--predictor-dtype bfloat16`), against PyTorch's float32 call: a speed bought with accuracy,
  not parity (the predicted means' max |diff| from float32 is printed).
Times are medians over --repeats rounds after a warm-up; every round calls each function once, in
a shuffled order, after a short pause (--pause-ms) so that neither library's idle worker threads
are still spinning when the other one starts; all calls see the same background load. The JAX
compile time of each row is reported apart, and the load average before and after the run.
torch is optional (never a runtime dependency; the `bench` extra): without it only JAX is timed.
`--json` writes every measured number (per batch: the rows, the roofline, the load) and
`--render` replaces the `<!-- predict-table -->` block of a Markdown page with the table rendered
from that JSON (`--render-only`: from the stored JSON, measuring nothing).

Then the roofline (`_roofline.py`): the forward pass's GFLOP, the rate each library reaches on
it, and the float32 matmul rates of the network's own shapes on this machine, so a target such as
"3x PyTorch" can be checked against what the machine can do at all: a forward pass takes at
least GFLOP / (best matmul rate), an input gradient at least twice that (one backward product
per forward product).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import random
import statistics
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from _markdown import replace_block
from _roofline import forward_gflop, matmul_rates, matmul_shapes

from diffsense.predictors import (
    init_predictor,
    CSLSTMPredictor,
    load_predictor,
    predict_mean,
    predict_model_frame,
    si_to_model,
    state_dict_from_model,
)
from diffsense.scene import SCENE_DT_S, load_scenario
from diffsense.tracks import CSLSTM_SPEC, prediction_frames

ROOT = Path(__file__).resolve().parent.parent

OPS = {  # row key -> label
    "forward": "forward",
    "all_modes": "all 6 modes",
    "gradient": "input gradient",
    "forward_bf16": "forward, bf16 products",
    "gradient_bf16": "input gradient, bf16 products",
}
TORCH_OP = {"all_modes": "forward", "forward_bf16": "forward", "gradient_bf16": "gradient"}  # the torch call compared


def _inputs(b: int, n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    hist = np.stack([25 * 0.2 * np.arange(-15, 1)[None].repeat(b, 0), rng.normal(0, 0.3, (b, 16))], -1)
    nbr_hist = hist[:, None] + rng.normal(0, 10, (b, n, 1, 2))
    slot = np.stack([rng.choice([s for s in range(39) if s != 19], n, replace=False) for _ in range(b)])
    weight = np.ones((b, n))
    return hist.astype(np.float32), nbr_hist.astype(np.float32), slot.astype(np.int32), weight.astype(np.float32)


def _time_interleaved(fns: dict, repeats: int, pause_s: float, seed: int = 0) -> dict[str, float]:
    """Median seconds per call of each function over `repeats` rounds (see the module doc)."""
    for fn in fns.values():
        fn()  # warm-up
    order, rng = list(fns), random.Random(seed)
    times = {name: [] for name in fns}
    for _ in range(repeats):
        rng.shuffle(order)
        for name in order:
            time.sleep(pause_s)
            t0 = time.perf_counter()
            fns[name]()
            times[name].append(time.perf_counter() - t0)
    return {name: statistics.median(t) for name, t in times.items()}


def _compiled(fn, *args) -> tuple:
    t0 = time.perf_counter()
    exe = jax.jit(fn).lower(*args).compile()
    return exe, time.perf_counter() - t0


def _jax_fns(predictor: CSLSTMPredictor, args):
    hist, nbr_hist, slot, weight = (jnp.asarray(a) for a in args)

    def loss(hist, nbr_hist, weight, p, slot):
        return jnp.sum(predict_mean(p, hist, nbr_hist, slot, weight))

    def all_modes(p, hist, nbr_hist, slot, weight):
        return predict_model_frame(p, si_to_model(hist), si_to_model(nbr_hist), slot, weight)

    fast = dataclasses.replace(predictor, product_dtype="bfloat16")
    jobs = {
        "forward": (predict_mean, (predictor, hist, nbr_hist, slot, weight)),
        "gradient": (jax.grad(loss, argnums=(0, 1, 2)), (hist, nbr_hist, weight, predictor, slot)),
        "forward_bf16": (predict_mean, (fast, hist, nbr_hist, slot, weight)),
        "gradient_bf16": (jax.grad(loss, argnums=(0, 1, 2)), (hist, nbr_hist, weight, fast, slot)),
    }
    if predictor.maneuvers:
        jobs["all_modes"] = (all_modes, (predictor, hist, nbr_hist, slot, weight))
    fns, compile_s = {}, {}
    for op, (fn, a) in jobs.items():
        exe, compile_s[op] = _compiled(fn, *a)
        fns[op] = lambda exe=exe, a=a: jax.block_until_ready(exe(*a))
    return fns, compile_s


def pipeline_batch() -> tuple[int, str]:
    """(B, where it came from): the targets one E(r) evaluation of the default problem predicts,
    counted from its configuration without building a scene."""
    from diffsense import Problem

    traffic = Problem.from_toml().traffic
    instants = [len(prediction_frames(int(round(load_scenario(name).duration_s / SCENE_DT_S)) + 1,
                                      traffic.prediction_stride_frames, CSLSTM_SPEC, SCENE_DT_S))
                for name in traffic.scenarios]
    batch = traffic.variants * sum(instants)
    per = f"{instants[0]}" if len(set(instants)) == 1 else "+".join(map(str, instants))
    # five vehicles per scenario (ego, target, lead, target's lead, adjacent) and its background
    others = {4 + (traffic.background_vehicles or load_scenario(name).background.count) for name in traffic.scenarios}
    return batch, (f"the default problem's {len(instants)} scenarios x {traffic.variants} variants x {per} "
                   f"prediction instants (one every {traffic.prediction_stride_frames} frames); its targets have "
                   f"{'/'.join(map(str, sorted(others)))} candidate neighbours each (`--neighbours` sets this benchmark's)")


def _measure(batch: int, neighbours: int, predictors, args, torch) -> dict:
    """One batch's rows (printed as they come) and roofline."""
    inputs = _inputs(batch, neighbours)
    load0 = os.getloadavg()
    print(f"\nCS-LSTM, B = {batch}, {neighbours} neighbours per target, float32, CPU "
          f"({os.cpu_count()} cores); median of {args.repeats} interleaved rounds")
    print(f"{'variant':<10} {'op':<29} {'jax [ms]':>9} {'torch [ms]':>11} {'speed-up':>9} {'jax compile [s]':>16}")
    rows, times, bf16_max_diff = [], [], {}
    for predictor in predictors:
        name = "manoeuvre" if predictor.maneuvers else "single"
        fns, compile_s = _jax_fns(predictor, inputs)
        timed = {f"jax_{k}": v for k, v in fns.items()}
        agree = None
        if torch is not None:
            from _torch_reference import torch_fns

            ref = np.asarray(jax.jit(predict_mean)(predictor, *inputs))
            tfns, agree = torch_fns(state_dict_from_model(predictor.model()), inputs, ref)
            timed |= {f"torch_{k}": v for k, v in tfns.items()}
        t = _time_interleaved(timed, args.repeats, args.pause_ms / 1e3)
        times.append((name, t))
        for op, label in OPS.items():
            if f"jax_{op}" not in t:
                continue
            t_jax, t_torch = t[f"jax_{op}"], t.get(f"torch_{TORCH_OP.get(op, op)}")
            torch_txt = f"{1e3 * t_torch:11.1f}" if t_torch else f"{'-':>11}"
            speedup = f"{t_torch / t_jax:8.1f}x" if t_torch else f"{'-':>9}"
            print(f"{name:<10} {label:<29} {1e3 * t_jax:9.1f} {torch_txt} {speedup} {compile_s[op]:16.1f}")
            rows.append({"variant": name, "op": op, "jax_ms": 1e3 * t_jax,
                         "torch_ms": None if t_torch is None else 1e3 * t_torch, "jax_compile_s": compile_s[op]})
        if agree is not None:
            print(f"{'':<10} (torch vs jax predicted mean: max |diff| = {agree:.2e} m)")
        bf16_diff = float(np.max(np.abs(np.asarray(fns["forward_bf16"]()) - np.asarray(fns["forward"]()))))
        print(f"{'':<10} (bf16 products vs float32 predicted mean: max |diff| = {bf16_diff:.2e} m)")
        bf16_max_diff[name] = bf16_diff
    roofline = _print_roofline(batch, neighbours, times, torch)
    load1 = os.getloadavg()
    print(f"load average (1, 5, 15 min): before {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}, "
          f"after {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}")
    if max(load0[0], load1[0]) > 0.5 * (os.cpu_count() or 1):
        print("warning: the machine was busy. PyTorch's OpenMP workers slow down far more than XLA's "
              "under contention, so the speed-ups above overstate a quiet machine's.")
    return {"batch": batch, "neighbours": neighbours, "repeats": args.repeats, "rows": rows, "roofline": roofline,
            "bf16_max_diff_m": bf16_max_diff,
            "load_before": load0[0], "load_after": load1[0]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", default=None,
                        help="batch sizes, comma-separated (default: the pipeline's own, printed)")
    parser.add_argument("--neighbours", type=int, default=12)
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--pause-ms", type=float, default=20.0, help="pause before every timed call")
    parser.add_argument("--checkpoint", default=None, help="weights to use (default: random init of both variants)")
    parser.add_argument("--json", type=Path, default=None, help="write the results here")
    parser.add_argument("--render", type=Path, default=None, help="Markdown page whose predict-table block is re-rendered")
    parser.add_argument("--render-only", action="store_true", help="render the stored --json, measure nothing")
    args = parser.parse_args()
    if args.render_only:
        if args.json is None or args.render is None:
            raise SystemExit("error: --render-only needs --json and --render")
        res = json.loads(args.json.read_text())
        print("\n".join(table(res)))
        replace_block(args.render, "predict-table", render_body(res))
        return
    source, pipeline = None, None
    if args.batch is None:
        pipeline, source = pipeline_batch()
        batches = [pipeline]
        print(f"B = {pipeline}: {source}")
    else:
        batches = [int(b) for b in str(args.batch).split(",") if b]
    try:
        import torch

        torch_version = f"{torch.__version__} ({torch.get_num_threads()} threads)"
    except ImportError:
        torch, torch_version = None, None
    if args.checkpoint:
        predictors = [load_predictor(args.checkpoint)]
    else:
        predictors = [init_predictor(maneuvers=m, seed=0) for m in (False, True)]
    print(f"jax {jax.__version__}, torch {torch_version}")
    runs = [_measure(b, args.neighbours, predictors, args, torch) for b in batches]
    res = {"runs": runs, "meta": {"machine": platform.platform(), "cpus": os.cpu_count(), "jax": jax.__version__,
                                  "torch": torch_version, "checkpoint": args.checkpoint,
                                  "pipeline_batch": pipeline, "pipeline_batch_source": source}}
    if args.json is not None:
        kept = json.loads(args.json.read_text())["runs"] if args.json.exists() else []
        fresh = {r["batch"] for r in runs}  # batches not measured again keep their stored results
        res["runs"] = sorted([r for r in kept if r["batch"] not in fresh] + runs, key=lambda r: r["batch"])
        if pipeline is None and args.json.exists():
            old = json.loads(args.json.read_text())["meta"]
            res["meta"]["pipeline_batch"], res["meta"]["pipeline_batch_source"] = old.get("pipeline_batch"), old.get("pipeline_batch_source")
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(res, indent=1) + "\n")
        print(f"\nwrote {args.json}")
    print("\n".join(table(res)))
    if args.render is not None:
        replace_block(args.render, "predict-table", render_body(res))
        print(f"rendered the table into {args.render}")


def table(res: dict) -> list[str]:
    """The results as a Markdown table: one row per batch, variant and operation."""
    lines = ["| B | rounds | variant | op | JAX [ms] | PyTorch [ms] | speed-up | JAX forward [GFLOP/s] | load |",
             "|---|---|---|---|---|---|---|---|---|"]
    for run in res["runs"]:
        gflop = run["roofline"]["forward_gflop"]
        for row in run["rows"]:
            t_torch = row["torch_ms"] if row["op"] not in TORCH_OP else next(
                (r["torch_ms"] for r in run["rows"] if r["variant"] == row["variant"] and r["op"] == TORCH_OP[row["op"]]), None)
            rate = f"{gflop / (row['jax_ms'] / 1e3):.0f}" if row["op"] == "forward" else ""
            torch_txt = "-" if t_torch is None else f"{t_torch:.1f}"
            speedup = "-" if t_torch is None else f"{t_torch / row['jax_ms']:.1f}x"
            lines.append(f"| {run['batch']} | {run['repeats']} | {row['variant']} | {OPS[row['op']]} | {row['jax_ms']:.1f} | {torch_txt} | "
                         f"{speedup} | {rate} | {run['load_before']:.1f}-{run['load_after']:.1f} |")
    return lines


def render_body(res: dict) -> str:
    rates = ["| B | product | m x k x n | XLA [GFLOP/s] | XLA, bf16 operands [GFLOP/s] | PyTorch [GFLOP/s] |",
             "|---|---|---|---|---|---|"]
    for run in res["runs"]:
        for name, r in run["roofline"]["matmul"].items():
            m, k, n = r["shape"]
            torch_txt = "-" if r.get("torch") is None else f"{r['torch']:.0f}"
            bf16_txt = "-" if r.get("xla_bf16") is None else f"{r['xla_bf16']:.0f}"
            rates.append(f"| {run['batch']} | {name} | {m} x {k} x {n} | {r['xla']:.0f} | {bf16_txt} | {torch_txt} |")
    diffs = "; ".join(f"B = {run['batch']}: " + ", ".join(f"{v} {d:.3f} m" for v, d in run["bf16_max_diff_m"].items())
                      for run in res["runs"] if run.get("bf16_max_diff_m"))
    meta = res["meta"]
    src = (f" B = {meta['pipeline_batch']} is the pipeline's own batch: {meta['pipeline_batch_source']}."
           if meta.get("pipeline_batch") else "")
    return "\n".join(table(res) + ["", f"Medians of `rounds` interleaved rounds on {meta['cpus']} cores "
                                       f"(jax {meta['jax']}, torch {meta['torch']}); `load` is the 1-minute load "
                                       f"average before and after each batch's run.{src}"
                                       + (f" The bf16 rows' predicted means differ from float32's by at most: {diffs}." if diffs else ""), "",
                                       "The float32 matmul rates of the network's own products on the same "
                                       "machine (best of 30):", ""] + rates)


def _print_roofline(batch: int, neighbours: int, rows, torch) -> dict:
    rates = matmul_rates(batch, neighbours, torch=torch)
    print("\nroofline: float32 matmul rates on this machine (best of 30) [GFLOP/s]")
    print(f"{'shape':<13} {'m x k x n':>18} {'xla':>7} {'torch':>7} {'xla, bf16 operands':>19}")
    shapes = matmul_shapes(batch, neighbours)
    for shape, (m, k, n) in shapes.items():
        r = rates[shape]
        torch_txt = f"{r['torch']:7.0f}" if "torch" in r else f"{'-':>7}"
        print(f"{shape:<13} {f'{m} x {k} x {n}':>18} {r['xla']:7.0f} {torch_txt} {r['xla_bf16']:19.0f}")
    best = max(v for r in rates.values() for name, v in r.items() if name != "xla_bf16")  # float32's
    gflop = forward_gflop(batch, neighbours)
    for name, t in rows:
        line = f"{name}: forward {gflop:.2f} GFLOP, jax {gflop / t['jax_forward']:.0f} GFLOP/s"
        if "torch_forward" in t:
            modes = 6 if name == "manoeuvre" else 1  # the reference decodes every manoeuvre
            t_torch = t["torch_forward"]
            line += (f", torch {forward_gflop(batch, neighbours, modes) / t_torch:.0f} GFLOP/s; 3x torch = "
                     f"{1e3 * t_torch / 3:.1f} ms needs {gflop / (t_torch / 3):.0f} GFLOP/s forward and "
                     f"{2 * gflop / (t['torch_gradient'] / 3):.0f} GFLOP/s at the least for the input gradient")
        print(line + f" (best matmul rate measured: {best:.0f} GFLOP/s)")
    return {"forward_gflop": gflop, "best_gflop_s": best,
            "matmul": {name: {"shape": list(shapes[name]), **rates[name]} for name in shapes}}


if __name__ == "__main__":
    main()
