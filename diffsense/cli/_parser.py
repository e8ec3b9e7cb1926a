"""The one argparse parser of every command: argparse's errors under the project's error contract."""

from __future__ import annotations

import argparse
from typing import NoReturn

from diffsense.runtime import InputError


class Parser(argparse.ArgumentParser):
    """`argparse.ArgumentParser` whose bad flag is an `InputError` naming the command as the user
    typed it (`prog`): one line `error: PROG: ...` and exit 2 under `diffsense.cli.run`, instead
    of argparse's usage dump. Sub-commands' parsers are of this class too (argparse builds them
    with the parent's class) and their `prog` is the parent's followed by the sub-command.
    Long options are never matched by a prefix (`allow_abbrev=False`)."""

    def __init__(self, *args, **kwargs):
        # No prefix matching of long options: `--predictor` must not be read as
        # `--predictor-dtype`, and a flag added later must not change an old command line.
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        raise InputError(f"{self.prog}: {message}")
