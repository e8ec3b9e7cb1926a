"""Training-set generation rate: simulation vs sample extraction vs writing, projected to 1M samples.

    python benchmarks/bench_traffic.py [--samples N] [--config FILE] [--out DIR]

Runs the shipped traffic config (configs/traffic/default.toml) in two ways:
1. staged: shard by shard, timing simulation, extraction and compaction + writing separately
   (each blocked on, so the stages do not overlap);
2. end to end: `write_dataset`, as `python -m diffsense.scene generate` runs it (the next batch
   is simulated while the current shard is written).
The compile time is measured once, on a first batch that is not counted. Rates are extrapolated
linearly to 1,000,000 samples (the work is a sequence of identical batches); the table says which
numbers are measured and which projected. The machine is shared: run it on a quiet machine for
numbers to quote.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import tempfile
import time
from pathlib import Path

import jax
import numpy as np

from diffsense import config
from diffsense.scene import TrafficConfig
from diffsense.train import (
    extract_batch,
    samples_per_simulation,
    shard_arrays,
    simulate_batch,
    simulation_keys,
    write_dataset,
)

TARGET = 1_000_000


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=300_000, help="samples per measured run (default 300000)")
    parser.add_argument("--config", help="traffic config (default: the shipped traffic/default.toml)")
    parser.add_argument("--out", help="folder for the written shards (default: a temporary folder, removed)")
    args = parser.parse_args()
    cfg = config.load(TrafficConfig, args.config) if args.config else config.load_default(TrafficConfig, "traffic/default.toml")
    batch = cfg.sampling.simulations_per_shard
    per_batch = batch * samples_per_simulation(cfg)
    num_batches = max(1, round(args.samples / per_batch))
    work = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bench_traffic_"))
    key = jax.random.key(0)
    print(f"jax {jax.__version__} on {jax.devices()[0].platform}, {os.cpu_count()} CPUs; load average {os.getloadavg()[0]:.1f}")
    print(f"config: {cfg.road.num_lanes} lanes x {cfg.road.vehicles_per_lane} vehicles, "
          f"{cfg.sampling.warmup_s:g} s warm-up + {4 + cfg.sampling.window_s + 5:g} s recorded at 10 Hz, "
          f"{samples_per_simulation(cfg)} samples per simulation, {batch} simulations ({per_batch} samples) per shard")

    t = time.perf_counter()
    warm = extract_batch(cfg, simulate_batch(cfg, simulation_keys(key, 10**6, batch)))
    jax.block_until_ready(warm)
    compile_s = time.perf_counter() - t

    sim_s = ext_s = write_s = 0.0
    samples = neighbours = 0
    cpu0 = time.process_time()
    try:
        for b in range(num_batches):
            t0 = time.perf_counter()
            traj = jax.block_until_ready(simulate_batch(cfg, simulation_keys(key, b * batch, batch)))
            t1 = time.perf_counter()
            dense = jax.block_until_ready(extract_batch(cfg, traj))
            t2 = time.perf_counter()
            shard = shard_arrays(cfg, b * batch, per_batch, dense)
            np.savez(work / f"staged_{b:05d}.npz", **shard)  # scratch files: no atomic publish needed
            t3 = time.perf_counter()
            sim_s, ext_s, write_s = sim_s + t1 - t0, ext_s + t2 - t1, write_s + t3 - t2
            samples += len(shard["hist"])
            neighbours += len(shard["nbr_hist"])
        staged_bytes = sum(p.stat().st_size for p in work.glob("staged_*.npz"))
        staged_cpu_s = time.process_time() - cpu0

        t, cpu0 = time.perf_counter(), time.process_time()
        meta = write_dataset(cfg, work / "dataset", samples, seed=0)
        e2e_s, e2e_cpu_s = time.perf_counter() - t, time.process_time() - cpu0
    finally:
        if not args.out:
            shutil.rmtree(work, ignore_errors=True)

    staged_s = sim_s + ext_s + write_s
    scale = TARGET / samples
    rows = [
        ("compile (first batch, not counted)", compile_s, None, "measured"),
        ("simulation (IDM + MOBIL, lax.scan, vmap)", sim_s, sim_s * scale, "measured / projected"),
        ("sample extraction (jit)", ext_s, ext_s * scale, "measured / projected"),
        ("compaction + writing .npz", write_s, write_s * scale, "measured / projected"),
        ("staged total", staged_s, staged_s * scale, "measured / projected"),
        ("end to end (write_dataset, pipelined)", e2e_s, e2e_s * scale, "measured / projected"),
    ]
    print(f"\n{samples} samples ({samples // samples_per_simulation(cfg)} simulations, {neighbours} neighbours, "
          f"{staged_bytes / samples:.0f} bytes per sample on disk) per run")
    print(f"{'stage':<44}{'time [s]':>10}{'samples/s':>12}{'1M samples [s]':>16}  {'':<}")
    for name, seconds, projected, how in rows:
        rate = f"{samples / seconds:12.0f}" if projected is not None else f"{'':>12}"
        proj = f"{projected:16.1f}" if projected is not None else f"{'':>16}"
        print(f"{name:<44}{seconds:10.2f}{rate}{proj}  {how}")
    lat, lon = meta["lat_label_counts"], meta["lon_label_counts"]
    n = meta["num_samples"]
    print(f"\nlabels: keep {lat['keep'] / n:.1%}, left {lat['left'] / n:.1%}, right {lat['right'] / n:.1%}; "
          f"braking {lon['braking'] / n:.1%}; neighbours per sample {meta['num_neighbours'] / n:.2f}")
    print(f"CPU time of this process (all threads; the machine is shared, load average now "
          f"{os.getloadavg()[0]:.1f}): staged {staged_cpu_s:.1f} s, end to end {e2e_cpu_s:.1f} s "
          f"-> {e2e_cpu_s * scale:.0f} CPU-s per 1M samples")
    print(f"peak resident memory of this process: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")
    print(f"1M samples end to end: {e2e_s * scale / 60:.1f} min projected (the issue asks < 10 min)")


if __name__ == "__main__":
    main()
