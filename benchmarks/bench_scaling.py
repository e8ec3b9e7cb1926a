"""How E's cost grows: value and value-and-gradient time against variants, scenarios and devices.

    python benchmarks/bench_scaling.py [--variants 8,16,32,64,128,256] [--base-scenarios 6]
        [--scenarios 1,2,4,6] [--base-variants 8] [--devices 1,4] [--sensor radar]
        [--param hfov_deg] [--interval 30 180] [--at 60] [--repeats 5] [--timeout-s 3600]
        [--json PATH]

Rows: every count in --variants (scene variants per scenario) at the first --base-scenarios of
the paper's six scenarios, then every count in --scenarios at --base-variants variants; each
for every device count in --devices (a configuration listed twice runs once). The problem is
the main job's (`diffsense.Problem.from_toml()`: float64, mean-field, the shipped CS-LSTM) with
those scenarios and variants; E is `diffsense.objective(problem)`, which shards the variants
over every JAX device (zero-weight padding to a multiple of the device count).

Every configuration runs in a fresh process of this script (`--worker`), with
XLA_FLAGS=--xla_force_host_platform_device_count=D and JAX_PLATFORMS=--platform set before jax
is imported, so D simulated CPU devices split the host's cores between them. In it:
- build [s]: `diffsense.objective(problem)` (scene simulation and ground-truth predictions);
- compile [s]: tracing, lowering and compiling the value program (E^2, the soft value the
  solver minimises) and the value-and-gradient program the solver runs
  (`diffsense.metrics.value_and_grad` of it: forward mode, as the parameter is one number), each
  with the objective as an argument (not folded in as constants), apart from the run time;
- value, value+grad [s]: medians over --repeats rounds after one warm-up call each; every round
  calls both programs, in a shuffled order;
- ratio = value+grad / value (issue #14's target: <= 2.5); reverse = the same ratio for
  reverse mode (`jax.value_and_grad`, what a problem of several parameters runs), timed in the
  same rounds; forward = the same ratio for forward mode with one tangent per parameter
  (`jax.jvp` vmapped over the k unit tangents inside `forward_mode()`), the alternative to
  reverse mode that a problem of k > 1 parameters has (with one parameter it is `ratio`);
- per scene [ms]: value+grad divided by the scenes (variants x scenarios);
- peak RSS [MB]: ru_maxrss of the worker process (imports, build, compile and runs together).
A configuration that fails (out of memory, --timeout-s) is reported as a row with its error
and the others still run. The load average is printed before and after; above 1.5 (on a 2-core
machine) the times are not speed figures.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RATIO_TARGET = 2.5  # issue #14: one value-and-gradient evaluation <= 2.5x one value evaluation
LOAD_WARNING = 1.5
MAX_SCENARIOS = 6  # the paper's six (diffsense.metrics.PAPER_SCENARIOS), taken in order
COLUMNS = ("devices", "variants", "scenarios", "scenes", "build [s]", "compile value / v+g [s]", "value [s]",
           "value+grad [s]", "ratio", "reverse", "forward", "v+g per scene [ms]", "peak RSS [MB]")


def _ints(text: str) -> list[int]:
    return [int(v) for v in text.split(",") if v.strip()]


def configurations(args) -> list[tuple[int, int, int]]:
    """(devices, variants, scenarios) of every row, in order, each once."""
    rows = [(v, args.base_scenarios) for v in _ints(args.variants)]
    rows += [(args.base_variants, s) for s in _ints(args.scenarios)]
    out = [(d, v, s) for d in _ints(args.devices) for v, s in rows]
    return list(dict.fromkeys(out))


def _programs(objective, r: dict) -> tuple[dict, dict[str, float]]:
    """The compiled value and value-and-gradient programs as thunks, and their compile times [s]."""
    import equinox as eqx
    import jax

    from diffsense.metrics import value_and_grad

    arrays, static = eqx.partition(objective, eqx.is_array)
    value = lambda a, r: eqx.combine(a, static).e2(r)  # noqa: E731
    jobs = {"value": value, "value_and_grad": lambda a, r: value_and_grad(lambda q: value(a, q))(r),
            "reverse": jax.value_and_grad(value, argnums=1)}
    if len(jax.tree.leaves(r)) > 1:
        jobs["forward"] = lambda a, r: _forward_tangents(lambda q: value(a, q), r)
    fns, compile_s = {}, {}
    for name, fn in jobs.items():
        t0 = time.perf_counter()
        exe = jax.jit(fn).lower(arrays, r).compile()
        compile_s[name] = time.perf_counter() - t0
        fns[name] = lambda exe=exe: jax.block_until_ready(exe(arrays, r))
    return fns, compile_s


def _forward_tangents(fn, r: dict):
    """(fn(r), its gradient) in forward mode: one tangent per number of r, `jax.jvp` vmapped."""
    import jax
    import jax.numpy as jnp

    from diffsense.predictors import forward_mode

    leaves, treedef = jax.tree.flatten(r)

    def along(unit):
        with forward_mode():
            return jax.jvp(fn, (r,), (jax.tree.unflatten(treedef, list(unit)),))

    value, slopes = jax.vmap(along, out_axes=(None, 0))(jnp.eye(len(leaves), dtype=leaves[0].dtype))
    return value, jax.tree.unflatten(treedef, list(slopes))


def worker(args) -> dict:
    """One configuration, in this (fresh) process: build, compile and time; one JSON-able row."""
    import jax
    from bench_predict import _time_interleaved  # the same shuffled rounds as the CS-LSTM benchmark

    import diffsense as ds
    from diffsense.metrics import PAPER_SCENARIOS

    load_before = os.getloadavg()[0]
    names = args.param.split(",")
    intervals = {name: tuple(args.interval[2 * k : 2 * k + 2]) for k, name in enumerate(names)}
    problem = ds.Problem.from_toml(sensor=args.sensor, params=intervals,
                                   scenarios=PAPER_SCENARIOS[:args.worker_scenarios], variants=args.worker_variants)
    t0 = time.perf_counter()
    objective = ds.objective(problem)
    jax.block_until_ready(objective)
    build_s = time.perf_counter() - t0
    r = {name: jax.numpy.asarray(at, objective.dtype) for name, at in zip(problem.params, args.at, strict=True)}
    fns, compile_s = _programs(objective, r)
    median_s = _time_interleaved(fns, args.repeats, pause_s=0.0)
    scenes = args.worker_variants * len(problem.traffic.scenarios)
    return {
        "devices": jax.device_count(), "sharded_over": len(objective.data.weight.sharding.device_set),
        "variants": args.worker_variants, "scenarios": len(problem.traffic.scenarios), "scenes": scenes,
        "dtype": str(objective.dtype), "platform": jax.devices()[0].platform, "build_s": build_s,
        "compile_value_s": compile_s["value"], "compile_value_and_grad_s": compile_s["value_and_grad"],
        "value_s": median_s["value"], "value_and_grad_s": median_s["value_and_grad"],
        "ratio": median_s["value_and_grad"] / median_s["value"],
        "reverse_ratio": median_s["reverse"] / median_s["value"], "params": list(problem.params),
        "forward_ratio": median_s.get("forward", median_s["value_and_grad"]) / median_s["value"],
        "value_and_grad_per_scene_ms": 1e3 * median_s["value_and_grad"] / scenes,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "repeats": args.repeats, "load_before": load_before, "load_after": os.getloadavg()[0],
    }


def _worker_command(args, devices: int, variants: int, scenarios: int) -> tuple[list[str], dict]:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", "--worker-variants", str(variants),
           "--worker-scenarios", str(scenarios), "--sensor", args.sensor, "--param", args.param,
           "--interval", *map(str, args.interval), "--at", *map(str, args.at), "--repeats", str(args.repeats)]
    flags = os.environ.get("XLA_FLAGS", "")
    env = dict(os.environ, XLA_FLAGS=f"{flags} --xla_force_host_platform_device_count={devices}".strip())
    if args.platform:
        env["JAX_PLATFORMS"] = args.platform
    return cmd, env


def run_configuration(args, devices: int, variants: int, scenarios: int) -> dict:
    """The worker's row for one configuration; a row with "error" if it failed."""
    cmd, env = _worker_command(args, devices, variants, scenarios)
    row = {"devices": devices, "variants": variants, "scenarios": scenarios, "scenes": variants * scenarios}
    try:
        done = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=args.timeout_s)
    except subprocess.TimeoutExpired:
        return row | {"error": f"over --timeout-s {args.timeout_s:g}"}
    if done.returncode != 0:
        why = " (killed: out of memory?)" if done.returncode in (-9, 137) else ""
        tail = done.stderr.strip().splitlines()[-1:] or [""]
        return row | {"error": f"exit {done.returncode}{why} {tail[0][:200]}".strip()}
    out = json.loads(done.stdout.strip().splitlines()[-1])
    if out["sharded_over"] != devices:
        print(f"warning: {devices} devices asked for, the objective's data spans {out['sharded_over']}",
              file=sys.stderr)
    return out


def _cells(row: dict) -> list[str]:
    head = [str(row[k]) for k in ("devices", "variants", "scenarios", "scenes")]
    if "error" in row:
        return head + [f"failed: {row['error']}"] + [""] * (len(COLUMNS) - len(head) - 1)
    return head + [f"{row['build_s']:.1f}", f"{row['compile_value_s']:.1f} / {row['compile_value_and_grad_s']:.1f}",
                   f"{row['value_s']:.3f}", f"{row['value_and_grad_s']:.3f}", f"{row['ratio']:.2f}", f"{row['reverse_ratio']:.2f}", _forward_cell(row),
                   f"{row['value_and_grad_per_scene_ms']:.1f}", f"{row['peak_rss_mb']:.0f}"]


def _forward_cell(row: dict) -> str:
    return f"{row['forward_ratio']:.2f}" if "forward_ratio" in row else "-"  # rows from before the column


def table(rows: list[dict]) -> str:
    """The rows as a markdown table."""
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    return "\n".join(lines + ["| " + " | ".join(_cells(row)) + " |" for row in rows])


def _load_line(when: str) -> str:
    load = os.getloadavg()
    line = f"load average (1, 5, 15 min) {when}: {load[0]:.2f}, {load[1]:.2f}, {load[2]:.2f} on {os.cpu_count()} cores"
    if load[0] > LOAD_WARNING:
        line += f"\nwarning: load above {LOAD_WARNING}: other work shares the machine; these times are not speed figures"
    return line


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--variants", default="8,16,32,64,128,256", help="variants per scenario, one row each")
    p.add_argument("--base-scenarios", type=int, default=6, help="scenarios of the --variants rows")
    p.add_argument("--scenarios", default="1,2,4,6", help="scenario counts, one row each ('' for none)")
    p.add_argument("--base-variants", type=int, default=8, help="variants per scenario of the --scenarios rows")
    p.add_argument("--devices", default="1,4", help="JAX device counts (simulated host devices)")
    p.add_argument("--platform", default="cpu", help="JAX_PLATFORMS of the workers ('' leaves it unset)")
    p.add_argument("--sensor", default="radar")
    p.add_argument("--param", default="hfov_deg",
                   help="the free parameters (the sensor's names for them), comma-separated")
    p.add_argument("--interval", type=float, nargs="+", default=(30.0, 180.0),
                   help="their bounds, two numbers per parameter")
    p.add_argument("--at", type=float, nargs="+", default=(60.0,), help="the point r every call evaluates")
    p.add_argument("--repeats", type=int, default=5, help="timed rounds per configuration")
    p.add_argument("--timeout-s", type=float, default=3600.0, help="limit per configuration")
    p.add_argument("--json", default=None, help="also write the rows and the machine's load here")
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--worker-variants", type=int, default=8, help=argparse.SUPPRESS)
    p.add_argument("--worker-scenarios", type=int, default=6, help=argparse.SUPPRESS)
    return p


def main() -> None:
    parser = _parser()
    args = parser.parse_args()
    counts = [args.base_scenarios, *_ints(args.scenarios)]
    if not all(1 <= s <= MAX_SCENARIOS for s in counts):
        parser.error(f"scenario counts must lie in 1..{MAX_SCENARIOS}, got {counts}")
    k = len(args.param.split(","))
    if len(args.interval) != 2 * k or len(args.at) != k:
        parser.error(f"{k} parameter(s) need {2 * k} --interval numbers and {k} --at, "
                     f"got {len(args.interval)} and {len(args.at)}")
    if args.worker:
        print(json.dumps(worker(args)))
        return
    print(_load_line("before"), flush=True)
    load_before, rows = os.getloadavg(), []
    for devices, variants, scenarios in configurations(args):
        t0 = time.perf_counter()
        rows.append(run_configuration(args, devices, variants, scenarios))
        print(f"  {devices} device(s), {variants} variants x {scenarios} scenarios: "
              f"{time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    print(table(rows))
    over = [r for r in rows if "ratio" in r and r["ratio"] > RATIO_TARGET]
    print(f"value+grad / value <= {RATIO_TARGET}: " + ("met in every row" if not over else
          "missed in " + ", ".join(f"{r['devices']} dev x {r['variants']} var x {r['scenarios']} sc" for r in over)))
    print(_load_line("after"))
    if args.json:
        Path(args.json).write_text(json.dumps({"rows": rows, "load_before": load_before, "load_after": os.getloadavg(),
                                               "cpu_count": os.cpu_count(), "argv": sys.argv[1:]}, indent=1) + "\n")


if __name__ == "__main__":
    main()
