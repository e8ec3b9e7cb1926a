"""`diffsense`: the one console command, a subcommand for each face of the library.

    diffsense optimise --param hfov --interval 30 180    # the main job (python -m diffsense.optimise)
    diffsense inspect --sensor radar --hfov 30           # a setting on boresight (python -m diffsense.sensors inspect)
    diffsense scene show sc01 --out sc01.png             # a scenario drawn (python -m diffsense.scene)
    diffsense generate --out DIR                         # CS-LSTM training traffic (python -m diffsense.scene generate)
    diffsense train --config FILE                        # train the CS-LSTM on it (python -m diffsense.train)
    diffsense predict card                               # the shipped model card (python -m diffsense.predictors)
    diffsense case-study FILE...                         # the case study's tables

`diffsense COMMAND --help` prints the command's own flags, under the name `diffsense COMMAND`.
Every command runs under the one error contract (`diffsense.cli.run`): bad input is one `error:`
line and exit 2, Ctrl-C exits 130.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

from diffsense.cli import case_study, generate, optimise, predict, run, scene, sensors, train
from diffsense.runtime import InputError, __version__

# name -> (what it does, its main(argv, prog))
COMMANDS: dict[str, tuple[str, Callable[[list[str], str], int]]] = {
    "optimise": ("find the sensor parameters that minimise the prediction error (the main job)", optimise.main),
    "inspect": ("what a sensor setting means for a vehicle on boresight, and its coverage", sensors.inspect),
    "scene": ("draw or list the scenarios", scene.main),
    "generate": ("write a CS-LSTM training set from simulated traffic", generate.main),
    "train": ("train the CS-LSTM on a generated training set", train.main),
    "predict": ("the predictor: parity with the PyTorch reference, the model card", predict.main),
    "case-study": ("the case study's tables from benchmarks/case_study.py's results", case_study.main),
}


def usage(prog: str = "diffsense") -> str:
    width = max(map(len, COMMANDS))
    lines = [f"usage: {prog} COMMAND [ARGS ...]   (diffsense {__version__})", "", "commands:"]
    lines += [f"  {name:<{width}}  {what}" for name, (what, _) in COMMANDS.items()]
    lines += ["", f"{prog} COMMAND --help: the command's own flags"]
    return "\n".join(lines)


def main(argv: list[str] | None = None, prog: str = "diffsense") -> int:
    """Run `prog COMMAND ARGS...`: the command's main with its own name, `prog COMMAND`."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] in (["-h"], ["--help"]):
        print(usage(prog))
        return 0
    if argv[:1] == ["--version"]:
        print(f"diffsense {__version__}")
        return 0
    if not argv:
        raise InputError(f"{prog}: a command is needed: {', '.join(COMMANDS)} ({prog} --help)")
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        raise InputError(f"{prog}: unknown command {name!r} (known: {', '.join(COMMANDS)})")
    return COMMANDS[name][1](rest, f"{prog} {name}")


def console() -> None:
    """The `diffsense` console script."""
    run(main, end_process=True)
