"""Scene engine benchmark: the six scenarios x 32 variants x 20 s, and the relevant set's size.

    python benchmarks/bench_scene.py [--variants 32] [--repeats 5] [--background 100]

Prints, per scenario, the first call (compilation + one run) and the best of `--repeats` runs
after compilation; the target is the six scenarios in under 1 s together. Then the vehicle count
the relevant set leaves (what every later stage pays for) without and with far background traffic.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import jax

from diffsense.config import replace
from diffsense.metrics import relevance_reach
from diffsense.predictors import CSLSTM_SPEC
from diffsense.sensors import make_sensor
from diffsense.scene import list_scenarios, load_scenario, relevant_vehicles, simulate_scenario


# The vehicles the CS-LSTM and either shipped sensor could need (the main job's own selection).
REACH = relevance_reach(CSLSTM_SPEC, [make_sensor("radar"), make_sensor("camera")])


def _timed(fn):
    start = time.perf_counter()
    out = jax.block_until_ready(fn())
    return out, time.perf_counter() - start


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--variants", type=int, default=32)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--background", type=int, default=100)
    args = p.parse_args()
    key = jax.random.key(0)
    print(f"jax {jax.__version__} on {jax.default_backend()}, {os.cpu_count()} CPU cores, {platform.processor() or platform.machine()}")
    print(f"\n{'scenario':<9} {'road':<9} {'shape [N,T,V]':<16} {'first call s':>13} {'run s':>9}")
    total_run = total_first = 0.0
    for name in list_scenarios():
        cfg = load_scenario(name)
        run = lambda: simulate_scenario(cfg, args.variants, key)  # noqa: E731
        scene, first = _timed(run)
        best = min(_timed(run)[1] for _ in range(args.repeats))
        total_run += best
        total_first += first
        shape = "x".join(str(n) for n in scene.s_m.shape)
        print(f"{name:<9} {cfg.road:<9} {shape:<16} {first:>13.3f} {best:>9.4f}")
    print(f"{'all six':<36} {total_first:>13.3f} {total_run:>9.4f}   (target: run < 1 s)")

    print(f"\nrelevant set of sc01 ({args.variants} variants): vehicles kept, and the time to find them")
    print(f"{'background':>10} {'V simulated':>12} {'V kept':>7} {'simulate s':>11} {'relevant s':>11}")
    for count in (0, args.background):
        cfg = replace(load_scenario("sc01"), background={"count": count})
        run = lambda: simulate_scenario(cfg, args.variants, key)  # noqa: E731
        scene, _ = _timed(run)
        sim = min(_timed(run)[1] for _ in range(args.repeats))
        kept, _ = _timed(lambda: relevant_vehicles(scene, **REACH))
        rel = min(_timed(lambda: relevant_vehicles(scene, **REACH))[1] for _ in range(args.repeats))
        print(f"{count:>10} {scene.num_vehicles:>12} {kept.num_vehicles:>7} {sim:>11.4f} {rel:>11.4f}")


if __name__ == "__main__":
    main()
