"""`diffsense generate` (and `python -m diffsense.scene generate`): write a CS-LSTM training set
from simulated traffic.

    diffsense generate --out DIR [--config FILE] [--samples N] [--seed S]

Without --config the shipped configs/traffic/default.toml is used; --samples and --seed override
the config's sampling.num_samples and sampling.seed.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import jax
from tqdm import tqdm

from diffsense import config
from diffsense.cli import Parser, setup_jax
from diffsense.scene import TrafficConfig

PROG = "python -m diffsense.scene generate"


def _parser(prog: str) -> argparse.ArgumentParser:
    p = Parser(prog=prog, description="Write a CS-LSTM training set from simulated traffic.")
    p.add_argument("--out", required=True, help="dataset folder to create (must not exist or be empty)")
    p.add_argument("--config", help="traffic config TOML (default: the shipped traffic/default.toml)")
    p.add_argument("--samples", type=int, help="number of samples (default: the config's sampling.num_samples)")
    p.add_argument("--seed", type=int, help="PRNG seed (default: the config's sampling.seed)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def main(argv: list[str] | None = None, prog: str = PROG) -> int:
    args = _parser(prog).parse_args(argv)
    cfg = config.load(TrafficConfig, args.config) if args.config else config.load_default(TrafficConfig, "traffic/default.toml")
    changes = {}
    if args.samples is not None:
        changes["num_samples"] = args.samples
    if args.seed is not None:
        changes["seed"] = args.seed
    if changes:
        cfg = config.replace(cfg, sampling=config.replace(cfg.sampling, **changes))
    from diffsense import train  # start-up: the training stack, only once the flags are good

    train.check_output_dir(Path(args.out))
    # The simulation is float32 whatever the x64 flag (the samples are float32): keep the flag.
    setup_jax(float64=bool(jax.config.read("jax_enable_x64")))

    start = time.perf_counter()
    n = cfg.sampling.num_samples
    with tqdm(total=n, unit="sample", unit_scale=True, disable=args.no_progress, file=sys.stderr) as bar:
        meta = train.write_dataset(cfg, args.out, n, cfg.sampling.seed, progress=bar.update)
    elapsed = time.perf_counter() - start
    lat, lon = meta["lat_label_counts"], meta["lon_label_counts"]
    print(
        f"wrote {meta['num_samples']} samples ({meta['num_neighbours']} neighbours, {len(meta['shards'])} shards, "
        f"{meta['num_simulations']} simulations) to {args.out} in {elapsed:.1f} s; "
        f"lateral keep/left/right {lat['keep']}/{lat['left']}/{lat['right']}, "
        f"braking {lon['braking']}"
    )
    return 0

