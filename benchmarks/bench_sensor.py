"""Benchmark: soft sensor detections for the paper's six scenarios x 32 variants (by hand).

    python benchmarks/bench_sensor.py [--variants 32] [--repeats 20] [--x64] [--synthetic]

For each sensor it times one jitted call over all 6 x N scenes (10 Hz, 20 s): soft p_detect and
noisy measurements (value), and the same with the gradient with respect to every sensor
parameter (value + grad: reverse mode, as `jax.value_and_grad`; value + grad fwd: forward mode,
one tangent per parameter). The measurement noise is either drawn inside the call from a key
("key") or drawn once beforehand ("drawn", `sensor.measurement_noise`), as a loop over r would.
Reported: compile time apart; per call after compilation the wall time (median and best of
`--repeats`) and the process CPU time (median; on a machine shared with other jobs the wall
time is inflated, the CPU time is what the call costs). Target: < 50 ms per call.
Scenes come from the scene engine (diffsense.scene), reduced to their relevant vehicles;
`--synthetic` uses straight-road scenes of 8 vehicles instead.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import jax
import jax.numpy as jnp
import numpy as np

TARGET_MS = 50.0


def engine_scenes(num_variants: int, dtype) -> list:
    from diffsense.metrics import relevance_reach
    from diffsense.predictors import CSLSTM_SPEC
    from diffsense.scene import list_scenarios, load_scenario, relevant_vehicles, simulate_scenario
    from diffsense.sensors import make_sensor

    reach = relevance_reach(CSLSTM_SPEC, [make_sensor("radar"), make_sensor("camera")])
    scenes = []
    for i, name in enumerate(list_scenarios()):
        batch = simulate_scenario(load_scenario(name), num_variants, jax.random.key(i), dtype=dtype)
        scenes.append(relevant_vehicles(batch, **reach))
    return scenes


def synthetic_scenes(num_variants: int, dtype, num_frames: int = 201, num_vehicles: int = 8):
    from diffsense.scene import Scene

    rng = np.random.default_rng(0)
    scenes = []
    for _ in range(6):
        shape = (num_variants, num_frames, num_vehicles)
        x0 = rng.uniform(-40.0, 120.0, (num_variants, 1, num_vehicles))
        x0[:, :, 0] = 0.0
        v = rng.uniform(20.0, 30.0, (num_variants, 1, num_vehicles))
        t = np.arange(num_frames)[None, :, None] * 0.1
        x = x0 + v * t
        y = np.broadcast_to(rng.integers(-1, 2, (num_variants, 1, num_vehicles)) * 3.7, shape)
        zeros = np.zeros(shape)
        a = lambda z: jnp.asarray(z, dtype)  # noqa: E731
        scenes.append(Scene(
            s_m=a(x), d_m=a(y), x_m=a(x), y_m=a(y), heading_rad=a(zeros), road_angle_rad=a(zeros),
            speed_mps=a(np.broadcast_to(v, shape)), lane=jnp.zeros(shape, jnp.int32),
            length_m=a(np.full((num_variants, num_vehicles), 4.5)),
            width_m=a(np.full((num_variants, num_vehicles), 1.8)),
            kind=jnp.zeros((num_variants, num_vehicles), jnp.int32),
            role=jnp.broadcast_to(jnp.minimum(jnp.arange(num_vehicles), 5), (num_variants, num_vehicles)),
            present=jnp.ones((num_variants, num_vehicles), bool)))
    return scenes


def make_objective(config):
    from diffsense import sensors as sensor

    def objective(params, scenes, noise):
        """`noise`: a key per scenario (drawn inside), or the pre-drawn standard normals."""
        total = 0.0
        for batch, draws in zip(scenes, noise):
            det = sensor.detect_batch(batch, params, config, draws)
            # something that needs both the probabilities and the measured positions
            total = total + jnp.mean(det.p_detect * (det.x_m + det.y_m))
        return total

    return objective


def value_and_grad_forward(fn):
    """value_and_grad of a scalar `fn(params, ...)` by forward mode: one linearisation and one
    tangent per parameter (vmapped). The sensor has a handful of scalar parameters and large
    per-frame arrays, so pushing 5 tangents forward costs less than storing residuals for a
    reverse pass."""
    from jax.flatten_util import ravel_pytree

    def vg(params, *args):
        flat, unravel = ravel_pytree(params)
        value, push = jax.linearize(lambda x: fn(unravel(x), *args), flat)
        grad = jax.vmap(push)(jnp.eye(flat.size, dtype=flat.dtype))
        return value, unravel(grad)

    return vg


def time_calls(fn, args, repeats: int):
    t0 = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    compile_s = time.perf_counter() - t0
    jax.block_until_ready(compiled(*args))  # warm-up
    times, cpu = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        jax.block_until_ready(compiled(*args))
        times.append(1e3 * (time.perf_counter() - t0))
        cpu.append(1e3 * (time.process_time() - c0))
    return compile_s, statistics.median(times), min(times), statistics.median(cpu)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--variants", type=int, default=32)
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--x64", action="store_true", help="float64 scenes and parameters")
    parser.add_argument("--synthetic", action="store_true", help="synthetic scenes, V = 8")
    args = parser.parse_args()
    jax.config.update("jax_enable_x64", args.x64)
    dtype = jnp.float64 if args.x64 else jnp.float32
    from diffsense import sensors as sensor

    t0 = time.perf_counter()
    scenes = (synthetic_scenes if args.synthetic else engine_scenes)(args.variants, dtype)
    build_s = time.perf_counter() - t0
    shapes = sorted({tuple(s.x_m.shape) for s in scenes})
    print(f"jax {jax.__version__} on {jax.devices()[0].device_kind}, {dtype.__name__}; "
          f"{len(scenes)} scenarios, scene batches [N, T, V] {shapes} "
          f"({'synthetic' if args.synthetic else 'scene engine'}, built in {build_s:.1f} s)")
    keys = [jax.random.fold_in(jax.random.key(0), i) for i in range(len(scenes))]
    drawn = [sensor.measurement_noise(k, s) for k, s in zip(keys, scenes)]
    header = (f"{'sensor':<8}{'noise':<8}{'call':<16}{'compile [s]':>12}{'median [ms]':>13}"
              f"{'best [ms]':>11}{'cpu [ms]':>10}  target < {TARGET_MS:g} ms")
    print(header)
    print("-" * len(header))
    for name in sensor.SENSORS:
        config = sensor.load_config(name)
        params = jax.tree.map(lambda v: jnp.asarray(v, dtype), config.params)
        objective = make_objective(config)
        for noise_label, noise in (("key", keys), ("drawn", drawn)):
            for label, fn in (("value", objective), ("value+grad", jax.value_and_grad(objective)),
                              ("value+grad fwd", value_and_grad_forward(objective))):
                compile_s, median_ms, best_ms, cpu_ms = time_calls(fn, (params, scenes, noise),
                                                                   args.repeats)
                verdict = "ok" if median_ms < TARGET_MS else "MISSED"
                print(f"{name:<8}{noise_label:<8}{label:<16}{compile_s:>12.2f}{median_ms:>13.1f}"
                      f"{best_ms:>11.1f}{cpu_ms:>10.1f}  {verdict}")
    print(f"load average (1, 5, 15 min) at the end: {os.getloadavg()} on {os.cpu_count()} cores")


if __name__ == "__main__":
    main()
