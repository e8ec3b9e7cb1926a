"""`python -m diffsense.train --config configs/train/default.toml [--resume] [--no-progress]`."""

from __future__ import annotations

import argparse

from diffsense import cli as _cli
from diffsense.runtime import InputError


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line and exit 2, like every other bad input
        raise InputError(f"{self.prog}: {message}")


def main(argv: list[str] | None = None) -> int:
    parser = _Parser(prog="python -m diffsense.train", description="Train the CS-LSTM on generated traffic.")
    parser.add_argument("--config", required=True, help="training config TOML (configs/train/default.toml)")
    parser.add_argument("--resume", action="store_true", help="continue from the run's last checkpoint")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    from diffsense import config
    from diffsense.train import TrainConfig

    cfg = config.load(TrainConfig, args.config)
    _cli.setup_jax(float64=False)
    from diffsense.train import train

    card = train(cfg, resume=args.resume, progress=not args.no_progress)
    rmse = card["validation"]["rmse_m"]
    print(f"wrote {cfg.run.weights} ({card['steps']} steps, {card['wall_time_s']:.0f} s)")
    print("horizon [s]        " + " ".join(f"{h:>6d}" for h in card["validation"]["horizon_s"]))
    for name, values in rmse.items():
        print(f"{name:<18} " + " ".join(f"{v:6.2f}" for v in values))
    return 0


if __name__ == "__main__":
    _cli.run(main, end_process=True)
