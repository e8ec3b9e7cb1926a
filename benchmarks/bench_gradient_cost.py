"""What a gradient costs in a design problem: value-and-gradient against a value, per suite.

    python benchmarks/bench_gradient_cost.py [--suites radar_camera_d8,...] [--variants 1]
        [--scenarios sc01,sc03] [--draws 32] [--repeats 5] [--json PATH]

For each shipped suite file (configs/suites/NAME.toml) under its members' laws (the physical
profile's by default): the design objective's soft value E^2 (the estimator `auto` picks:
relaxed-reference over K draws under the physical laws, mean-field under the threshold law) and
its value-and-gradient in reverse mode, each one compiled program, timed `--repeats` times
after a warm-up call at the suite's defaults (clipped into its box). The ratio is the cost of a
gradient in values: the target is <= 2.5 at every d. Medians; the machine's load before and
after goes into the JSON.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import equinox as eqx
import jax
import numpy as np

import diffsense as ds

ROOT = Path(__file__).resolve().parents[1]
SUITES = "radar_camera_d4,radar_camera_d8,radar_camera_mounted_d14,corner_radars_camera_d28"


@eqx.filter_jit
def _value(E, r):
    return E.e2(r)


@eqx.filter_jit
def _value_and_grad(E, r):
    return jax.value_and_grad(E.e2)(r)


def _median_s(fn, *args, repeats: int) -> float:
    jax.block_until_ready(fn(*args))  # compile and warm
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def measure(name: str, variants: int, scenarios: list[str], draws: int, repeats: int) -> dict:
    problem = ds.Problem.from_suite(ROOT / "configs" / "suites" / f"{name}.toml", variants=variants,
                                    scenarios=scenarios, estimator=ds.metrics.EstimatorConfig(reference_draws=draws))
    E = ds.objective(problem)
    defaults = E.sensor.defaults()
    r = {n: jax.numpy.asarray(min(max(defaults[n], lo), hi), E.dtype) for n, (lo, hi) in problem.params.items()}
    value = _median_s(_value, E, r, repeats=repeats)
    both = _median_s(_value_and_grad, E, r, repeats=repeats)
    return {"suite": name, "d": len(problem.params), "estimator": E.estimator_kind, "draws": draws,
            "value_s": value, "value_and_grad_s": both, "ratio": both / value}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--suites", default=SUITES, help="comma-separated suite names (configs/suites/)")
    p.add_argument("--variants", type=int, default=1)
    p.add_argument("--scenarios", default="sc01,sc03")
    p.add_argument("--draws", type=int, default=32, help="reference draws K")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--json", type=Path, default=None)
    args = p.parse_args()
    load_before = os.getloadavg()
    rows = [measure(s, args.variants, args.scenarios.split(","), args.draws, args.repeats) for s in args.suites.split(",")]
    print(f"{'suite':<28} {'d':>3} {'estimator':<18} {'value s':>9} {'v+g s':>9} {'ratio':>6}")
    for row in rows:
        print(f"{row['suite']:<28} {row['d']:>3} {row['estimator']:<18} {row['value_s']:>9.3f} "
              f"{row['value_and_grad_s']:>9.3f} {row['ratio']:>6.2f}")
    out = {"rows": rows, "variants": args.variants, "scenarios": args.scenarios, "repeats": args.repeats,
           "load_before": load_before, "load_after": os.getloadavg(), "jax": jax.__version__}
    if args.json:
        args.json.write_text(json.dumps(out, indent=1) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
