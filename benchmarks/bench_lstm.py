"""Benchmark: the LSTM recurrences of CS-LSTM against the alternatives they were chosen over.

    python benchmarks/bench_lstm.py [--repeats 20]

Shapes of bench_predict.py (B = 128 targets, 12 neighbours, float32, CPU): the encoder runs
16 steps over N = 13 x 128 = 1664 histories (input 32, hidden 64); the decoder 25 steps over 128
rows (one mode) or 768 (all 6 modes; input 117, hidden 128). Rows, each timed as the median (and
minimum) of --repeats interleaved rounds after a warm-up, with XLA's temporary memory:
- forward: `diffsense.predictors._lstm` (Python-unrolled) against a `lax.scan` of the same cell.
- input gradient: the hand-written backward, with the gates kept or recomputed in the backward
  pass (REMAT_BYTES forced either way), against JAX's autodiff of a textbook `lax.scan` LSTM.
- input tangent: forward mode (`diffsense.predictors.forward_mode`, one tangent along the inputs,
  what a one-parameter E(r) needs), with the primal and tangent rows in one product per step or
  in two (this project stacks them below STACK_ROWS rows).
- a sum over the leading axis of a [16, 1664, 256] array: `x.sum(0)` against 15 additions.
- the per-step matmuls alone, XLA against PyTorch (MKL), in GFLOP/s: the ceiling that the
  recurrences run against (when torch, the `bench` extra, is installed).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import statistics
import time

import jax
import jax.numpy as jnp
import numpy as np

from diffsense.predictors import _lstm, _lstm_forward


def _scan_lstm(xs, w_ih, w_hh, b):
    """The textbook LSTM (logistic gates), one `lax.scan` step per time step."""

    def step(carry, x):
        h, c = carry
        i, f, g, o = jnp.split(x @ w_ih + h @ w_hh + b, 4, axis=-1)
        c = jax.nn.sigmoid(f) * c + jax.nn.sigmoid(i) * jnp.tanh(g)
        h = jax.nn.sigmoid(o) * jnp.tanh(c)
        return (h, c), h

    zeros = jnp.zeros((xs.shape[1], w_hh.shape[0]), xs.dtype)
    return jax.lax.scan(step, (zeros, zeros), xs)[1]


def _problem(steps, n, n_in, hidden, repeated, seed=0):
    rng = np.random.default_rng(seed)
    shape = (n, n_in) if repeated else (steps, n, n_in)
    weights = ((n_in, 4 * hidden), (hidden, 4 * hidden), (4 * hidden,))
    arrays = [rng.normal(size=shape), *(rng.uniform(-0.3, 0.3, s) for s in weights)]
    return [jnp.asarray(a, jnp.float32) for a in arrays]


def _variants(steps, repeated):
    """(this project's LSTM, the lax.scan one) as functions of (x, w_ih, w_hh, b)."""
    ours = (lambda x, *w: _lstm.lstm_repeat(steps, x, *w)) if repeated else (lambda x, *w: _lstm.lstm_last(x, *w))
    seq = (lambda x: jnp.broadcast_to(x, (steps,) + x.shape)) if repeated else (lambda x: x)
    scan = (lambda x, *w: _scan_lstm(seq(x), *w)) if repeated else (lambda x, *w: _scan_lstm(x, *w)[-1])
    return ours, scan


def _compile(fn, args, remat_bytes=None, forward=False, stack_rows=None):
    saved = _lstm.REMAT_BYTES, _lstm_forward.STACK_ROWS
    if remat_bytes is not None:
        _lstm.REMAT_BYTES = remat_bytes  # read while tracing
    if stack_rows is not None:
        _lstm_forward.STACK_ROWS = stack_rows
    try:
        t0 = time.perf_counter()
        with _lstm_forward.forward_mode() if forward else contextlib.nullcontext():
            exe = jax.jit(fn).lower(*args).compile()
        compile_s = time.perf_counter() - t0
    finally:
        _lstm.REMAT_BYTES, _lstm_forward.STACK_ROWS = saved
    return exe, compile_s, exe.memory_analysis().temp_size_in_bytes / 2**20


def _rows(steps, n, n_in, hidden, repeated):
    args = _problem(steps, n, n_in, hidden, repeated)
    ours, scan = _variants(steps, repeated)
    grad = lambda f: jax.grad(lambda *a: jnp.sum(jnp.tanh(f(*a))))  # a nonlinear read-out
    # the same read-out's derivative along one input direction (a single-parameter E(r) needs one)
    tangent = lambda f: lambda x, *w: jax.jvp(lambda x: jnp.sum(jnp.tanh(f(x, *w))), (x,), (jnp.ones_like(x),))
    return {
        "forward, unrolled (this project)": _compile(ours, args),
        "forward, lax.scan": _compile(scan, args),
        "input gradient, gates kept": _compile(grad(ours), args, remat_bytes=2**62),
        "input gradient, gates recomputed": _compile(grad(ours), args, remat_bytes=0),
        "input gradient, autodiff of lax.scan": _compile(grad(scan), args),
        "input tangent, rows stacked": _compile(tangent(ours), args, forward=True, stack_rows=2**62),
        "input tangent, rows apart": _compile(tangent(ours), args, forward=True, stack_rows=0),
    }, args


def _time(jobs: dict, repeats: int) -> dict:
    for exe, args in jobs.values():
        jax.block_until_ready(exe(*args))
    times = {k: [] for k in jobs}
    for _ in range(repeats):
        for k, (exe, args) in jobs.items():
            t0 = time.perf_counter()
            jax.block_until_ready(exe(*args))
            times[k].append(time.perf_counter() - t0)
    return {k: (statistics.median(v), min(v)) for k, v in times.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    args = parser.parse_args()
    load0 = os.getloadavg()
    print(f"float32, CPU ({os.cpu_count()} cores), jax {jax.__version__}; "
          f"median (min) of {args.repeats} interleaved rounds")
    print(f"{'case':<38} {'median [ms]':>11} {'min [ms]':>9} {'temp [MiB]':>11} {'compile [s]':>12}")
    for title, shape in (("encoder T=16 N=1664", (16, 1664, 32, 64, False)),
                         ("decoder T=25 N=128", (25, 128, 117, 128, True)),
                         ("decoder T=25 N=768", (25, 768, 117, 128, True))):
        rows, a = _rows(*shape)
        t = _time({k: (exe, a) for k, (exe, _, _) in rows.items()}, args.repeats)
        print(title)
        for k, (_, compile_s, temp) in rows.items():
            print(f"  {k:<36} {1e3 * t[k][0]:11.2f} {1e3 * t[k][1]:9.2f} {temp:11.1f} {compile_s:12.2f}")
    x = jnp.asarray(np.random.default_rng(1).normal(size=(16, 1664, 256)), jnp.float32)
    sums = {
        "x.sum(0)": jax.jit(lambda a: a.sum(0)),
        "15 additions": jax.jit(lambda a: sum(a[k] for k in range(1, 16)) + a[0]),
    }
    t = _time({k: (f, (x,)) for k, f in sums.items()}, args.repeats)
    print("sum over the leading axis of [16, 1664, 256]")
    for k in sums:
        print(f"  {k:<36} {1e3 * t[k][0]:11.2f} {1e3 * t[k][1]:9.2f}")
    _matmuls(args.repeats)
    load1 = os.getloadavg()
    print(f"load average (1 min): before {load0[0]:.2f}, after {load1[0]:.2f}")


def _matmuls(repeats: int) -> None:
    try:
        import torch
    except ImportError:
        return
    rng = np.random.default_rng(2)
    shapes = {
        "encoder step [1664,96]@[96,256]": (1664, 96, 256),
        "encoder backward [1664,256]@[256,96]": (1664, 256, 96),
        "decoder step [128,128]@[128,512]": (128, 128, 512),
        "6 modes [768,128]@[128,512]": (768, 128, 512),
    }
    jobs = {}
    for name, (m, k, n) in shapes.items():
        a, b = (rng.normal(size=s).astype(np.float32) for s in ((m, k), (k, n)))
        jobs[(name, "xla")] = (jax.jit(lambda x, y: x @ y), (jnp.asarray(a), jnp.asarray(b)))
        ta, tb = torch.from_numpy(a), torch.from_numpy(b)
        jobs[(name, "torch")] = (lambda x, y, ta=ta, tb=tb: ta @ tb, (None, None))
    t = _time(jobs, repeats)
    print(f"matmuls, GFLOP/s at the median (min) time; torch {torch.__version__}, {torch.get_num_threads()} threads")
    for name, (m, k, n) in shapes.items():
        flop = 2 * m * k * n
        (xm, xn), (tm, tn) = t[(name, "xla")], t[(name, "torch")]
        print(f"  {name:<36} xla {flop / xm / 1e9:6.0f} ({flop / xn / 1e9:4.0f})   "
              f"torch {flop / tm / 1e9:6.0f} ({flop / tn / 1e9:4.0f})")


if __name__ == "__main__":
    main()
