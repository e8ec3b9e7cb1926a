"""`python -m diffsense.scene generate`: write a CS-LSTM training set from simulated traffic.

    python -m diffsense.scene generate --out DIR [--config FILE] [--samples N] [--seed S]

Without --config the shipped configs/traffic/default.toml is used; --samples and --seed override
the config's sampling.num_samples and sampling.seed.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from diffsense.runtime import InputError


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line and exit 2 (via diffsense._cli.run), no usage dump
        raise InputError(message)


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="python -m diffsense.scene generate", description=__doc__.splitlines()[0])
    p.add_argument("--out", required=True, help="dataset folder to create (must not exist or be empty)")
    p.add_argument("--config", help="traffic config TOML (default: the shipped traffic/default.toml)")
    p.add_argument("--samples", type=int, help="number of samples (default: the config's sampling.num_samples)")
    p.add_argument("--seed", type=int, help="PRNG seed (default: the config's sampling.seed)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point; `argv` excludes the word `generate`."""
    args = _parser().parse_args(sys.argv[1:] if argv is None else argv)
    from diffsense import config
    from diffsense.cli import setup_jax
    from diffsense.scene import TrafficConfig

    cfg = config.load(TrafficConfig, args.config) if args.config else config.load_default(TrafficConfig, "traffic/default.toml")
    changes = {}
    if args.samples is not None:
        changes["num_samples"] = args.samples
    if args.seed is not None:
        changes["seed"] = args.seed
    if changes:
        cfg = config.replace(cfg, sampling=config.replace(cfg.sampling, **changes))

    import jax
    from tqdm import tqdm

    from diffsense.train import check_output_dir, write_dataset

    check_output_dir(Path(args.out))
    # The simulation is float32 whatever the x64 flag (the samples are float32): keep the flag.
    setup_jax(float64=bool(jax.config.read("jax_enable_x64")))

    start = time.perf_counter()
    n = cfg.sampling.num_samples
    with tqdm(total=n, unit="sample", unit_scale=True, disable=args.no_progress, file=sys.stderr) as bar:
        meta = write_dataset(cfg, args.out, n, cfg.sampling.seed, progress=bar.update)
    elapsed = time.perf_counter() - start
    lat, lon = meta["lat_label_counts"], meta["lon_label_counts"]
    print(
        f"wrote {meta['num_samples']} samples ({meta['num_neighbours']} neighbours, {len(meta['shards'])} shards, "
        f"{meta['num_simulations']} simulations) to {args.out} in {elapsed:.1f} s; "
        f"lateral keep/left/right {lat['keep']}/{lat['left']}/{lat['right']}, "
        f"braking {lon['braking']}"
    )
    return 0


if __name__ == "__main__":
    from diffsense.cli import run

    run(main, end_process=True)
