"""File output that keeps its promises: no half-written file, no folder mixing two runs, no
temporary left behind by an interrupt.

- `atomic_open` (and `write_bytes`, `write_json`, `save_figure`): a temporary file in the
  destination folder, flushed and fsynced, then `os.replace`d onto its name (atomic on POSIX within
  one filesystem). The file gets the mode `0o666 & ~umask`, like any file the user creates
  (`mkstemp` alone gives 0600 whatever the umask).
- `output_set(out_dir)`: a run writes all its files into a staging folder and they are published
  together into `out_dir`, replacing the previous run's set (see its docstring).
- `check_writable(out_dir)`: the up-front test a command runs before any computation.
- Every temporary this module creates is registered until it is renamed or removed;
  `abandon_temporaries()` deletes them all for a signal handler about to end the process. The
  registry and every publish share one lock, so that handler (run from another thread, see
  `diffsense.cli.run`) sees either the temporaries or the finished set, never a half-published one.
  Publications into one folder also take turns across processes (`_lock.folder_lock`).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import signal
import tempfile
import threading
from collections.abc import Iterator, Mapping
from pathlib import Path, PurePosixPath
from typing import Any, BinaryIO

from diffsense.runtime._errors import InputError
from diffsense.runtime._lock import LOCK_FILE, folder_lock

MANIFEST = "manifest.json"
_MANIFEST_FORMAT = "diffsense-output-set"
_LOCK = threading.RLock()
_TEMPORARIES: dict[str, str] = {}  # path -> "file" | "tree" | "dir" (a folder made for a set)


def register_temporary(path: str | os.PathLike[str], kind: str = "tree") -> None:
    """Mark `path` (a "file" or a folder "tree") for removal if the process is interrupted
    (SIGINT/SIGTERM under `diffsense.cli.run`); `release_temporary` once it has been published."""
    with _LOCK:
        _TEMPORARIES[str(path)] = kind


def release_temporary(path: str | os.PathLike[str]) -> None:
    """`path` is no longer temporary (published, or removed by its owner)."""
    with _LOCK:
        _TEMPORARIES.pop(str(path), None)


def _file_mode() -> int:
    """The mode a new file gets under the process umask (read from /proc; os.umask as fallback)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return 0o666 & ~int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    with _LOCK:  # os.umask can only be read by setting it; 0o022 is a safe value for the instant
        mask = os.umask(0o022)
        os.umask(mask)
    return 0o666 & ~mask


def abandon_temporaries() -> None:
    """Delete every registered temporary and keep the registry lock for good.

    For a handler that ends the process right after: holding the lock, no temporary can be created
    and no output set published after the sweep, and none is half published during it.
    """
    _LOCK.acquire()
    for path, kind in reversed(list(_TEMPORARIES.items())):  # contents before the folders made for them
        if kind == "tree":
            shutil.rmtree(path, ignore_errors=True)
        else:
            with contextlib.suppress(OSError):
                (os.rmdir if kind == "dir" else os.unlink)(path)
    _TEMPORARIES.clear()


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike[str]) -> Iterator[BinaryIO]:
    """Open `path` for binary writing; it appears under its name only if the block succeeds."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with _LOCK:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        _TEMPORARIES[tmp] = "file"
    try:
        os.fchmod(fd, _file_mode())
        with os.fdopen(fd, "wb") as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        with _LOCK:
            os.replace(tmp, path)
            del _TEMPORARIES[tmp]
    except BaseException:
        with _LOCK:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
            _TEMPORARIES.pop(tmp, None)
        raise


def write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Write `data` to `path` atomically."""
    with atomic_open(path) as f:
        f.write(data)


def json_ready(value: Any) -> Any:
    """`value` as strict JSON can hold it: tuples to lists, numpy / jax scalars and arrays to
    Python, every non-finite float (NaN, +-inf) to None (null); another type is a TypeError."""
    if isinstance(value, Mapping):
        return {str(k): json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    if hasattr(value, "tolist"):  # numpy / jax arrays and scalars
        return json_ready(value.tolist())
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if value is None or isinstance(value, (bool, int, str)):
        return value
    raise TypeError(f"cannot write {type(value).__name__} to JSON")


def write_json(path: str | os.PathLike[str], obj: Any) -> None:
    """Write `obj` as indented, strict JSON to `path` atomically: a non-finite number is null,
    never the `NaN` / `Infinity` that JSON parsers other than Python's refuse."""
    text = json.dumps(json_ready(obj), indent=2, sort_keys=False, allow_nan=False)
    write_bytes(path, (text + "\n").encode())


def save_figure(fig: Any, path: str | os.PathLike[str], **kwargs: Any) -> None:
    """Save a matplotlib figure atomically (format taken from the suffix of `path`)."""
    fmt = Path(path).suffix.lstrip(".") or "png"
    with atomic_open(path) as f:
        fig.savefig(f, format=fmt, **kwargs)


def check_writable(out_dir: str | os.PathLike[str]) -> None:
    """Raise InputError (one line) unless `out_dir` is, or can be created as, a writable folder.

    Contract: call it before any computation, so a run never spends minutes and then fails to
    save. It creates nothing that outlives it: for a missing `out_dir` it probes the nearest
    existing ancestor (which must be a folder: a path under a regular file is refused) by creating
    and deleting a file there, which also catches read-only mounts and access lists that
    permission bits do not show.
    """
    out = Path(out_dir)
    try:
        base = out
        while not base.exists() and not base.is_symlink() and base.parent != base:
            base = base.parent
        if not base.is_dir():
            where = "exists" if base == out else f"lies under {base}, which exists"
            raise InputError(f"output folder {out} {where} and is not a folder")
        fd, probe = tempfile.mkstemp(dir=base, prefix=".diffsense-probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise InputError(f"output folder {out} is not writable ({base}: {e.strerror})") from None


def _make_folders(out: Path) -> list[Path]:
    """Create `out` and its missing parents; the ones created, outermost first."""
    missing = []
    while not out.is_dir() and out.parent != out:
        missing.append(out)
        out = out.parent
    made = []
    for folder in reversed(missing):
        with contextlib.suppress(FileExistsError):
            folder.mkdir()
            made.append(folder)
    return made


@contextlib.contextmanager
def output_set(out_dir: str | os.PathLike[str]) -> Iterator[Path]:
    """A fresh staging folder whose files are published into `out_dir` as one set on success.

    Contract. `with output_set(out) as staging:` yields an empty folder on `out`'s filesystem
    (a hidden `.staging-*` inside `out`: beside it would need `out`'s parent to be writable, which
    fails for `--out /tmp`). Write every output of the run into it, sub-folders allowed. When the
    block succeeds, the set is published, holding the folder's lock (`.diffsense.lock`, which every
    process publishing into `out` takes, so concurrent runs leave the whole set of the one that
    published last), then the registry lock, deferring SIGINT/SIGTERM:
    - `out/manifest.json` lists the previous set's files (relative paths); those files, and
      sub-folders they leave empty, are removed: nothing else in `out` is ever touched, so files
      the user keeps there survive, and a folder holds exactly one run's set;
    - the new files are moved in (`os.replace`), `manifest.json` last, listing them (a folder
      without a manifest, a first run's, loses only the files the new set overwrites);
    - a new file that would replace a folder is refused (InputError) before anything changes.
    When the block raises, or the process is interrupted (see `diffsense.cli.run`), the staging
    folder, and `out` itself if this call created it and it is empty, are removed; the previous
    set stays as it was. Only a hard kill during the few renames of a publish can mix two sets.
    """
    out = Path(out_dir)
    with _LOCK:
        made = _make_folders(out)
        staging = Path(tempfile.mkdtemp(dir=out, prefix=".staging-"))
        _TEMPORARIES.update({str(m): "dir" for m in made})
        _TEMPORARIES[str(staging)] = "tree"
    try:
        yield staging
        # The folder's lock first: a signal that arrives while another process publishes still
        # ends this one at once (the registry lock is free for the handler; nothing has moved).
        with folder_lock(out), _LOCK, _signals_deferred():
            _publish(staging, out)
            shutil.rmtree(staging, ignore_errors=True)
            for m in made:
                _TEMPORARIES.pop(str(m), None)
            _TEMPORARIES.pop(str(staging), None)
    except BaseException:
        with _LOCK:
            shutil.rmtree(staging, ignore_errors=True)
            _TEMPORARIES.pop(str(staging), None)
            for m in reversed(made):
                with contextlib.suppress(OSError):
                    m.rmdir()
                _TEMPORARIES.pop(str(m), None)
        raise


def _set_files(folder: Path) -> list[str]:
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if not p.is_dir())


def published_files(out_dir: str | os.PathLike[str]) -> list[str]:
    """The files of the output set published in `out_dir` (its manifest's list; [] without one):
    what a run wrote, for the line that says so."""
    return _previous_files(Path(out_dir))


def _previous_files(out: Path) -> list[str]:
    """The files the previous set's manifest lists (only plain relative paths inside `out`)."""
    try:
        manifest = json.loads((out / MANIFEST).read_text())
        files = manifest["files"] if manifest.get("format") == _MANIFEST_FORMAT else []
    except (OSError, ValueError, TypeError, KeyError, AttributeError):
        return []
    ok = [f for f in files if isinstance(f, str) and f]
    return [f for f in ok if not PurePosixPath(f).is_absolute() and ".." not in PurePosixPath(f).parts]


def _publish(staging: Path, out: Path) -> None:
    files = _set_files(staging)
    if MANIFEST in files or LOCK_FILE in files:
        raise ValueError(f"an output set cannot contain its own {MANIFEST} or {LOCK_FILE}")
    for rel in files:
        target = out / rel
        if target.is_dir() and not target.is_symlink():
            raise InputError(f"cannot publish {rel} into {out}: a folder of that name is in the way")
        for parent in target.relative_to(out).parents:
            if (out / parent).exists() and not (out / parent).is_dir():
                raise InputError(f"cannot publish {rel} into {out}: {out / parent} is a file")
    old = _previous_files(out)
    for rel in sorted(set(old) - set(files)):
        with contextlib.suppress(FileNotFoundError, IsADirectoryError, NotADirectoryError):
            (out / rel).unlink()
        parent = (out / rel).parent
        while parent != out and parent.is_dir() and not any(parent.iterdir()):
            parent.rmdir()
            parent = parent.parent
    for rel in files:
        (out / rel).parent.mkdir(parents=True, exist_ok=True)
        os.replace(staging / rel, out / rel)
    write_json(staging / MANIFEST, {"format": _MANIFEST_FORMAT, "version": 1, "files": files})
    os.replace(staging / MANIFEST, out / MANIFEST)


@contextlib.contextmanager
def _signals_deferred() -> Iterator[None]:
    """Hold SIGINT/SIGTERM's Python handlers for the block, then deliver what arrived.

    Keeps a library caller's Ctrl-C (a KeyboardInterrupt) out of the middle of a publish. Only the
    main thread can swap handlers; elsewhere the block runs as is.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []
    old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    old = {s: h for s, h in old.items() if h is not None}  # None: a handler not set from Python
    for s in old:
        signal.signal(s, lambda signum, _frame: pending.append(signum))
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        for signum in pending:
            signal.raise_signal(signum)
