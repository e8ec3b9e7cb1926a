"""What every command-line entry point shares: the exit-code contract and JAX start-up.

Only CLI modules import this. `run(main)` calls `main()` and keeps these promises:
- an `InputError` becomes one line `error: <message>` on stderr, exit code 2 (never a traceback);
  so does an `OSError` (a read-only folder, a path under a file, a full disk): `error: <path>:
  <reason>`;
- SIGINT (Ctrl-C), at any moment, prints the one line `interrupted` and exits 130; SIGTERM prints
  `terminated` and exits 143 (128 + the signal number, as a shell reports a signal); neither leaves
  a temporary file, staging folder or half-published output set behind (`diffsense.runtime`'s
  output sets). Before `run` starts, a command's start-up is covered by the handlers `import
  diffsense` installs in a command's process (`diffsense/__init__.py`): the same line and code.

Why not KeyboardInterrupt: a Ctrl-C that lands while JAX runs a host callback
(`jax.pure_callback`) raises inside the callback, and XLA re-raises it as a `ValueError` with a
long traceback. So `run` never lets the signal become an exception. Its Python-level handlers do
nothing; Python's C-level handler also writes the signal number to a wake-up pipe
(`signal.set_wakeup_fd`) the moment the signal arrives, whatever the main thread is doing, and a
watcher thread reading that pipe removes the registered temporaries, prints the line and ends the
process with `os._exit`. The watcher needs only the GIL, which the main thread releases while XLA
compiles or computes and every few milliseconds while it runs Python.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

import jax

from diffsense import runtime
from diffsense.runtime import InputError

_SIGNALS = {signal.SIGINT: ("interrupted", 130), signal.SIGTERM: ("terminated", 143)}


def run(main: Callable[[], int | None], *, end_process: bool = False) -> None:
    """Run a CLI `main` under the project's error contract and exit with its code.

    `end_process` (the entry points: `python -m ...` and the console scripts): once `main`
    returns, its output flushed and its files published, end the process at once with
    `os._exit`, skipping the interpreter's teardown of JAX's objects (0.5-0.7 s on the 2-core
    machine, nothing left to save). Not in a multi-process run, whose processes leave
    `jax.distributed` at exit; not in-process (tests), where `run` raises SystemExit as it does
    on failure.
    """
    try:
        with _signals_end_the_process():
            code = main()
    except InputError as e:
        _fail(str(e))
    except OSError as e:
        where = " -> ".join(str(f) for f in (e.filename, e.filename2) if f is not None)
        _fail(f"{where}: {e.strerror}" if where and e.strerror else str(e) or type(e).__name__)
    except KeyboardInterrupt:  # only where the handlers could not be set (not the main thread)
        print("interrupted", file=sys.stderr)
        sys.exit(130)
    if end_process and not _distributed():
        _flush_quietly()
        os._exit(code or 0)
    sys.exit(code or 0)


def _distributed() -> bool:
    return jax.process_count() > 1


MAX_ERROR_CHARS = 500  # an error line fits on a screen, whatever value it echoes


def _fail(message: str) -> None:
    line = " ".join(message.split())
    if len(line) > MAX_ERROR_CHARS:  # the head names the culprit; the rest is the echoed value
        line = f"{line[:MAX_ERROR_CHARS]}... ({len(line)} characters)"
    print(f"error: {line}", file=sys.stderr)
    sys.exit(2)


def _ignore(_signum: int, _frame: object) -> None:
    """The Python-level handler: the watcher thread does the work (see the module docstring)."""


@contextlib.contextmanager
def _signals_end_the_process() -> Iterator[None]:
    """For the block: SIGINT and SIGTERM end the process cleanly from a watcher thread.

    Restores the previous handlers and wake-up fd afterwards, so `run` can be called in-process
    (tests). Outside the main thread, where handlers cannot be set, the block runs as is.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    read_fd, write_fd = os.pipe()
    os.set_blocking(write_fd, False)  # set_wakeup_fd requires it
    watcher = threading.Thread(target=_watch, args=(read_fd,), name="diffsense-signals", daemon=True)
    watcher.start()
    previous_fd = signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
    previous = {s: signal.signal(s, _ignore) for s in _SIGNALS}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, signal.SIG_DFL if handler is None else handler)
        signal.set_wakeup_fd(previous_fd)
        os.close(write_fd)  # the watcher reads end-of-file and returns
        watcher.join(timeout=5)


def _watch(read_fd: int) -> None:
    """Wait for a signal number on the wake-up pipe; end the process on SIGINT or SIGTERM."""
    try:
        while data := os.read(read_fd, 64):
            for signum in data:
                if signum in _SIGNALS:
                    _end(signum)
    finally:
        os.close(read_fd)


def _end(signum: int) -> None:
    line, code = _SIGNALS[signum]
    runtime.abandon_temporaries()  # keeps the lock: nothing new is created or published after it
    # Flush what the program already printed, from a helper thread: a flush blocked on a full
    # pipe must not stop the exit.
    flusher = threading.Thread(target=_flush_quietly, daemon=True)
    flusher.start()
    flusher.join(timeout=0.5)
    os.write(2, f"{line}\n".encode())
    os._exit(code)


def _flush_quietly() -> None:
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()


def setup_jax(float64: bool = True, compilation_cache: bool = True) -> None:
    """Configure JAX before the first computation: precision and the persistent compile cache.

    The cache lives in JAX_COMPILATION_CACHE_DIR when it is set, else in the user's cache
    directory (XDG_CACHE_HOME or ~/.cache)/diffsense/jax. Every program is cached, however
    quickly it compiled, so a second run of the same command compiles nothing. The objective's
    compiled programs are kept beside it, in `executables/` (`diffsense.runtime.keep_in`), so a
    second run does not trace them either.
    """
    jax.config.update("jax_enable_x64", float64)
    runtime.keep_in(None)
    if compilation_cache and os.environ.get("DIFFSENSE_NO_CACHE") != "1":
        base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
        cache_dir = Path(os.environ.get("JAX_COMPILATION_CACHE_DIR") or base / "diffsense" / "jax")
        try:
            cache_dir.mkdir(parents=True, exist_ok=True)
            jax.config.update("jax_compilation_cache_dir", str(cache_dir))
            jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
            jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
            runtime.keep_in(cache_dir / "executables")
        except OSError:
            pass  # a read-only home only costs speed
