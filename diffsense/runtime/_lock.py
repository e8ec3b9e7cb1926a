"""A lock that processes share: one publication at a time into an output folder.

The threading lock of `_io` orders the threads of one process; two runs into one `--out` are two
processes, and without this lock their publications interleave and leave both sets' files beside
one manifest.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
from collections.abc import Iterator
from pathlib import Path

LOCK_FILE = ".diffsense.lock"


@contextlib.contextmanager
def folder_lock(folder: Path) -> Iterator[None]:
    """Hold an exclusive lock on `folder` for the block, against every process and thread.

    An `flock` on `folder/.diffsense.lock`, a file that exists only while someone holds it, so the
    folder keeps only what the runs publish: the holder removes it before releasing the lock, and
    whoever then gets the lock on the removed file tries again on a fresh one. The kernel releases
    the lock of a process that dies; a file left by a hard kill is taken over by the next holder.
    """
    path = folder / LOCK_FILE
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            if _names(fd, path):
                break
        except BaseException:
            os.close(fd)
            raise
        os.close(fd)
    try:
        yield
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(path)
        os.close(fd)  # releases the lock


def _names(fd: int, path: Path) -> bool:
    """Whether `path` still names the file open as `fd` (its holder may have removed it)."""
    try:
        here = os.stat(path)
    except FileNotFoundError:
        return False
    held = os.fstat(fd)
    return (here.st_dev, here.st_ino) == (held.st_dev, held.st_ino)
