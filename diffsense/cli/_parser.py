"""The one argparse parser of every command: argparse's errors under the project's error contract."""

from __future__ import annotations

import argparse
from typing import NoReturn

from diffsense.runtime import InputError


class Parser(argparse.ArgumentParser):
    """`argparse.ArgumentParser` whose bad flag is an `InputError` naming the command as the user
    typed it (`prog`): one line `error: PROG: ...` and exit 2 under `diffsense.cli.run`, instead
    of argparse's usage dump. Sub-commands' parsers are of this class too (argparse builds them
    with the parent's class) and their `prog` is the parent's followed by the sub-command."""

    def error(self, message: str) -> NoReturn:
        raise InputError(f"{self.prog}: {message}")
