"""`diffsense scene` (and `python -m diffsense.scene`): the scenarios, drawn or listed.

    diffsense scene show sc01 --out sc01.png     # bird's-eye figure of a scenario
    diffsense scene show sc01 --json             # the scene as JSON on stdout
    diffsense scene list                         # the shipped scenarios and roads
    diffsense scene generate ...                 # training traffic (diffsense generate; its own --help)
"""

from __future__ import annotations

import argparse
import json
import sys

import jax

from diffsense.cli import Parser, generate, setup_jax
from diffsense.runtime import InputError, save_figure
from diffsense.scene import list_roads, list_scenarios, load_road, load_scenario, scene_figure, scene_json, simulate_scenario

PROG = "python -m diffsense.scene"
_FIGURE_SUFFIXES = (".png", ".pdf", ".svg")


def _parser(prog: str) -> argparse.ArgumentParser:
    p = Parser(prog=prog, description="Scenes of diffsense: view the paper's scenarios.")
    sub = p.add_subparsers(dest="command", required=True)
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
    cfg = load_scenario(args.scenario)
    road = load_road(cfg.road)
    batch = simulate_scenario(cfg, args.variant + 1, jax.random.key(args.seed), road=road)
    scene = jax.tree.map(lambda a: a[args.variant], batch)
    if args.json:
        json.dump(scene_json(scene, road, cfg.road), sys.stdout)
        sys.stdout.write("\n")
    if args.out:
        kind = "nominal" if args.variant == 0 else f"variant {args.variant}, seed {args.seed}"
        save_figure(scene_figure(scene, road, f"{cfg.description or cfg.name} ({kind})"), args.out, dpi=120)
        if not args.json:
            print(f"wrote {args.out}")
    return 0


def _list() -> int:
    for name in list_scenarios():
        cfg = load_scenario(name)
        print(f"{name}  road={cfg.road:<9} {cfg.description}")
    print("roads:", ", ".join(list_roads()))
    return 0


def main(argv: list[str] | None = None, prog: str = PROG) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["generate"]:  # its own flags, which the `show`/`list` parser would refuse
        return generate.main(argv[1:], f"{prog} generate")
    args = _parser(prog).parse_args(argv)
    return _show(args) if args.command == "show" else _list()
