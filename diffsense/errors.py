"""The one exception type a user can cause.

Every problem with what a user gave us (a config, a flag, a checkpoint, data) is raised as an
`InputError` whose message is a single line naming the problem. The command-line entry points
catch it, print `error: <message>` to stderr and exit with code 2; library callers can catch it
like any `ValueError`.
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad user input: one line that names the problem (the CLI exits with code 2)."""

    def __init__(self, message: str):
        # One line, always: a multi-line message would read like a traceback.
        super().__init__(" ".join(str(message).split()))
