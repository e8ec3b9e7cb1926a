"""`diffsense train` (and `python -m diffsense.train`): train the CS-LSTM on generated traffic.

    diffsense train --config configs/train/default.toml [--resume] [--no-progress]
"""

from __future__ import annotations

from diffsense import config
from diffsense.cli import Parser, setup_jax

PROG = "python -m diffsense.train"


def main(argv: list[str] | None = None, prog: str = PROG) -> int:
    parser = Parser(prog=prog, description="Train the CS-LSTM on generated traffic.")
    parser.add_argument("--config", required=True, help="training config TOML (configs/train/default.toml)")
    parser.add_argument("--resume", action="store_true", help="continue from the run's last checkpoint")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    from diffsense import train  # start-up: the training stack, only once the flags are good

    cfg = config.load(train.TrainConfig, args.config)
    setup_jax(float64=False)
    card = train.train(cfg, resume=args.resume, progress=not args.no_progress)
    rmse = card["validation"]["rmse_m"]
    print(f"wrote {cfg.run.weights} ({card['steps']} steps, {card['wall_time_s']:.0f} s)")
    print("horizon [s]        " + " ".join(f"{h:>6d}" for h in card["validation"]["horizon_s"]))
    for name, values in rmse.items():
        print(f"{name:<18} " + " ".join(f"{v:6.2f}" for v in values))
    return 0
