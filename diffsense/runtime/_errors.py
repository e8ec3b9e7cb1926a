"""The one exception type a user can cause.

Every problem with what a user gave us (a config, a flag, a checkpoint, data) is raised as an
`InputError` whose message is a single line naming the problem. The command-line entry points
catch it, print `error: <message>` to stderr and exit with code 2; library callers can catch it
like any `ValueError`.
"""

from __future__ import annotations

import math
from typing import Any


class InputError(ValueError):
    """Bad user input: one line that names the problem (the CLI exits with code 2)."""

    def __init__(self, message: str):
        # One line, always: a multi-line message would read like a traceback.
        super().__init__(" ".join(str(message).split()))


def finite_number(value: Any, what: str) -> float:
    """`value` as a finite float; InputError naming `what` otherwise."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{what} must be numbers, got {value!r}") from None
    if not math.isfinite(v):
        raise InputError(f"{what} must be finite numbers, got {value!r}")
    return v
