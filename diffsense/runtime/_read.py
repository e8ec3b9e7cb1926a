"""Reading a user's text file (a config, a suite) under the error contract: one `InputError` line
for a path that is not a regular file (a FIFO would block the run forever), a file larger than
any config, or bytes that are not UTF-8 text; a UTF-8 byte-order mark is accepted."""

from __future__ import annotations

import os
import stat
from pathlib import Path

from diffsense.runtime._errors import InputError

MAX_TEXT_BYTES = 1 << 20  # 1 MiB: the shipped configs are a few kB


def read_text_file(path: str | os.PathLike[str], what: str = "file", max_bytes: int = MAX_TEXT_BYTES) -> str:
    """The text of the regular file at `path`, decoded as UTF-8; `what` names it in errors."""
    path = Path(path)
    try:
        # O_NONBLOCK: opening a FIFO without a writer returns at once, and fstat then refuses it
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except FileNotFoundError:
        raise InputError(f"{what} not found: {path}") from None
    except OSError as e:
        raise InputError(f"cannot read {what} {path}: {e.strerror}") from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise InputError(f"{what} {path}: not a regular file")
    with os.fdopen(fd, "rb") as handle:
        data = handle.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise InputError(f"{what} {path}: larger than {max_bytes} bytes")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise InputError(f"{what} {path}: not UTF-8 text (byte 0x{data[e.start]:02x} at offset {e.start})") from None
