"""Benchmark: CS-LSTM forward and input-gradient time, JAX (this project) vs the PyTorch reference.

    python benchmarks/bench_predict.py [--repeats 30] [--batch 128] [--neighbours 12]
                                       [--checkpoint PATH] [--pause-ms 20]

B targets with N neighbours each (distinct random grid slots), float32, CPU. JAX runs the compact
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
Times are medians over --repeats rounds after a warm-up; every round calls each function once, in
a shuffled order, after a short pause (--pause-ms) so that neither library's idle worker threads
are still spinning when the other one starts; all calls see the same background load. The JAX
compile time of each row is reported apart, and the load average before and after the run.
torch is optional (never a runtime dependency; the `bench` extra): without it only JAX is timed.

Then the roofline (`_roofline.py`): the forward pass's GFLOP, the rate each library reaches on
it, and the float32 matmul rates of the network's own shapes on this machine, so a target such as
"3x PyTorch" can be checked against what the machine can do at all: a forward pass takes at
least GFLOP / (best matmul rate), an input gradient at least twice that (one backward product
per forward product).
"""

from __future__ import annotations

import argparse
import os
import random
import statistics
import time

import jax
import jax.numpy as jnp
import numpy as np
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

OPS = {  # row key -> label
    "forward": "forward",
    "all_modes": "all 6 modes",
    "gradient": "input gradient",
}


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

    jobs = {
        "forward": (predict_mean, (predictor, hist, nbr_hist, slot, weight)),
        "gradient": (jax.grad(loss, argnums=(0, 1, 2)), (hist, nbr_hist, weight, predictor, slot)),
    }
    if predictor.maneuvers:
        jobs["all_modes"] = (all_modes, (predictor, hist, nbr_hist, slot, weight))
    fns, compile_s = {}, {}
    for op, (fn, a) in jobs.items():
        exe, compile_s[op] = _compiled(fn, *a)
        fns[op] = lambda exe=exe, a=a: jax.block_until_ready(exe(*a))
    return fns, compile_s


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=128)
    parser.add_argument("--neighbours", type=int, default=12)
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--pause-ms", type=float, default=20.0, help="pause before every timed call")
    parser.add_argument("--checkpoint", default=None, help="weights to use (default: random init of both variants)")
    args = parser.parse_args()
    inputs = _inputs(args.batch, args.neighbours)
    try:
        import torch

        from _torch_reference import torch_fns

        torch_version = f"{torch.__version__} ({torch.get_num_threads()} threads)"
    except ImportError:
        torch_version = None
    if args.checkpoint:
        predictors = [load_predictor(args.checkpoint)]
    else:
        predictors = [init_predictor(maneuvers=m, seed=0) for m in (False, True)]
    load0 = os.getloadavg()
    print(f"CS-LSTM, B = {args.batch}, {args.neighbours} neighbours per target, float32, CPU "
          f"({os.cpu_count()} cores); median of {args.repeats} interleaved rounds; "
          f"jax {jax.__version__}, torch {torch_version}")
    print(f"{'variant':<10} {'op':<15} {'jax [ms]':>9} {'torch [ms]':>11} {'speed-up':>9} {'jax compile [s]':>16}")
    rows = []
    for predictor in predictors:
        name = "manoeuvre" if predictor.maneuvers else "single"
        fns, compile_s = _jax_fns(predictor, inputs)
        timed = {f"jax_{k}": v for k, v in fns.items()}
        agree = None
        if torch_version is not None:
            ref = np.asarray(jax.jit(predict_mean)(predictor, *inputs))
            tfns, agree = torch_fns(state_dict_from_model(predictor.model()), inputs, ref)
            timed |= {f"torch_{k}": v for k, v in tfns.items()}
        t = _time_interleaved(timed, args.repeats, args.pause_ms / 1e3)
        rows.append((name, t))
        for op, label in OPS.items():
            if f"jax_{op}" not in t:
                continue
            t_jax, t_torch = t[f"jax_{op}"], t.get(f"torch_{'forward' if op == 'all_modes' else op}")
            torch_txt = f"{1e3 * t_torch:11.1f}" if t_torch else f"{'-':>11}"
            speedup = f"{t_torch / t_jax:8.1f}x" if t_torch else f"{'-':>9}"
            print(f"{name:<10} {label:<15} {1e3 * t_jax:9.1f} {torch_txt} {speedup} {compile_s[op]:16.1f}")
        if agree is not None:
            print(f"{'':<10} (torch vs jax predicted mean: max |diff| = {agree:.2e} m)")
    _print_roofline(args.batch, args.neighbours, rows, torch if torch_version else None)
    load1 = os.getloadavg()
    print(f"load average (1, 5, 15 min): before {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}, "
          f"after {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}")
    if max(load0[0], load1[0]) > 0.5 * (os.cpu_count() or 1):
        print("warning: the machine was busy. PyTorch's OpenMP workers slow down far more than XLA's "
              "under contention, so the speed-ups above overstate a quiet machine's.")


def _print_roofline(batch: int, neighbours: int, rows, torch) -> None:
    rates = matmul_rates(batch, neighbours, torch=torch)
    print("\nroofline: float32 matmul rates on this machine (best of 30) [GFLOP/s]")
    print(f"{'shape':<13} {'m x k x n':>18} {'xla':>7} {'torch':>7}")
    for shape, (m, k, n) in matmul_shapes(batch, neighbours).items():
        r = rates[shape]
        torch_txt = f"{r['torch']:7.0f}" if "torch" in r else f"{'-':>7}"
        print(f"{shape:<13} {f'{m} x {k} x {n}':>18} {r['xla']:7.0f} {torch_txt}")
    best = max(v for r in rates.values() for v in r.values())
    for name, t in rows:
        gflop = forward_gflop(batch, neighbours)
        line = f"{name}: forward {gflop:.2f} GFLOP, jax {gflop / t['jax_forward']:.0f} GFLOP/s"
        if "torch_forward" in t:
            modes = 6 if name == "manoeuvre" else 1  # the reference decodes every manoeuvre
            t_torch = t["torch_forward"]
            line += (f", torch {forward_gflop(batch, neighbours, modes) / t_torch:.0f} GFLOP/s; 3x torch = "
                     f"{1e3 * t_torch / 3:.1f} ms needs {gflop / (t_torch / 3):.0f} GFLOP/s forward and "
                     f"{2 * gflop / (t['torch_gradient'] / 3):.0f} GFLOP/s at the least for the input gradient")
        print(line + f" (best matmul rate measured: {best:.0f} GFLOP/s)")


if __name__ == "__main__":
    main()
