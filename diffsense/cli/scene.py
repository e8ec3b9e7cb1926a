"""Scene command line.

    python -m diffsense.scene show sc01 --out sc01.png     # bird's-eye figure of a scenario
    python -m diffsense.scene show sc01 --json             # the scene as JSON on stdout
    python -m diffsense.scene list                         # the shipped scenarios and roads
    python -m diffsense.scene generate ...                 # training traffic (its own --help)
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys

from diffsense.cli import run, setup_jax
from diffsense.runtime import InputError

_FIGURE_SUFFIXES = (".png", ".pdf", ".svg")


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # argparse's usage dump + exit 2 -> our one line + exit 2
        raise InputError(message)


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="python -m diffsense.scene", description="Scenes of diffsense: view the paper's scenarios.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    show = sub.add_parser("show", help="draw or print one variant of a scenario")
    show.add_argument("scenario", help="a shipped scenario name (sc01 .. sc06) or a scenario .toml path")
    show.add_argument("--out", help="figure file to write (.png, .pdf or .svg)")
    show.add_argument("--json", action="store_true", help="print the scene as JSON instead of drawing it")
    show.add_argument("--variant", type=int, default=0, help="variant index: 0 nominal (default), K > 0 randomised")
    show.add_argument("--seed", type=int, default=0, help="seed of the randomised variants (default 0)")
    sub.add_parser("list", help="list the shipped scenarios and roads")
    sub.add_parser("generate", help="generate CS-LSTM training traffic (see: generate --help)", add_help=False)
    return p


def _show(args: argparse.Namespace) -> int:
    if args.variant < 0 or args.seed < 0:
        raise InputError(f"--variant and --seed must be >= 0, got {args.variant} and {args.seed}")
    if not args.json and not args.out:
        raise InputError("show needs --out FIGURE or --json")
    if args.out and not args.out.lower().endswith(_FIGURE_SUFFIXES):
        raise InputError(f"--out must end in one of {', '.join(_FIGURE_SUFFIXES)}, got {args.out!r}")
    setup_jax(float64=False)
    import jax

    from diffsense.scene import load_road, load_scenario, scene_figure, scene_json, simulate_scenario

    cfg = load_scenario(args.scenario)
    road = load_road(cfg.road)
    batch = simulate_scenario(cfg, args.variant + 1, jax.random.key(args.seed), road=road)
    scene = jax.tree.map(lambda a: a[args.variant], batch)
    if args.json:
        json.dump(scene_json(scene, road, cfg.road), sys.stdout)
        sys.stdout.write("\n")
    if args.out:
        from diffsense.runtime import save_figure

        kind = "nominal" if args.variant == 0 else f"variant {args.variant}, seed {args.seed}"
        save_figure(scene_figure(scene, road, f"{cfg.description or cfg.name} ({kind})"), args.out, dpi=120)
        if not args.json:
            print(f"wrote {args.out}")
    return 0


def _list() -> int:
    from diffsense.scene import list_roads, list_scenarios, load_scenario

    for name in list_scenarios():
        cfg = load_scenario(name)
        print(f"{name}  road={cfg.road:<9} {cfg.description}")
    print("roads:", ", ".join(list_roads()))
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["generate"]:
        try:
            generate = importlib.import_module("diffsense.cli.generate")
        except ModuleNotFoundError as e:
            if e.name != "diffsense.cli.generate":
                raise
            raise InputError("the training-traffic generator (diffsense.cli.generate) is not installed") from None
        return generate.main(argv[1:])
    args = _parser().parse_args(argv)
    return _show(args) if args.command == "show" else _list()


if __name__ == "__main__":
    run(main, end_process=True)
