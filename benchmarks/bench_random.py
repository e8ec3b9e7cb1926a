"""Benchmark: XLA compile time of `jax.random` draws of the project's shapes, shaped against flat.

    python benchmarks/bench_random.py [--repeats 5]

Each row compiles (`jax.jit(f).lower(key).compile()`, a new function each time, so nothing is
cached) a draw of one shape two ways, interleaved: `jax.random.normal(key, shape)` as JAX
makes it, and `diffsense.runtime.normal`, the same numbers drawn flat and reshaped. Medians
(and minimum) of --repeats compilations, float64, in the default threefry mode. The shapes are
the main job's: measurement noise of 48 variants x 201 frames x 5 vehicles (all at once, and one
variant's under vmap over 48 keys) and 64 Monte-Carlo uniform draws of one variant.
"""

from __future__ import annotations

import argparse
import statistics
import time

import jax
import jax.numpy as jnp

from diffsense import runtime

jax.config.update("jax_enable_x64", True)

KEYS = jax.random.split(jax.random.PRNGKey(0), 48)
ROWS = [
    ("normal [48, 2, 201, 5], one key", lambda draw: lambda k: draw("normal", k[0], (48, 2, 201, 5))),
    ("normal [2, 201, 5], vmap over 48 keys", lambda draw: jax.vmap(lambda kk: draw("normal", kk, (2, 201, 5)))),
    ("uniform [64, 201, 5], one key", lambda draw: lambda k: draw("uniform", k[0], (64, 201, 5))),
]


def _jax(kind, key, shape):
    return getattr(jax.random, kind)(key, shape, jnp.float64)


def _flat(kind, key, shape):
    return getattr(runtime, kind)(key, shape, jnp.float64)


def _compile_s(fn) -> float:
    start = time.perf_counter()
    jax.jit(lambda k: fn(k)).lower(KEYS).compile()
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    print(f"jax {jax.__version__}, threefry partitionable: {jax.config.jax_threefry_partitionable}")
    print(f"{'draw':<40} {'jax.random [s]':>16} {'flat [s]':>12} {'ratio':>7}")
    for name, make in ROWS:
        times = {"jax": [], "flat": []}
        for _ in range(args.repeats):
            times["jax"].append(_compile_s(make(_jax)))
            times["flat"].append(_compile_s(make(_flat)))
        a, b = statistics.median(times["jax"]), statistics.median(times["flat"])
        print(f"{name:<40} {a:9.2f} ({min(times['jax']):.2f}) {b:6.2f} ({min(times['flat']):.2f}) {a / b:6.1f}x")


if __name__ == "__main__":
    main()
