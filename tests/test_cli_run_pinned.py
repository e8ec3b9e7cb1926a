"""The command line's exit-code contract in-process, each promise by its exact text and code:
an InputError or OSError as one `error:` line and 2, main's code passed on, the signal handlers
and wake-up pipe set for the run and restored after it, a signal number on the pipe ending the
process with its line and 128 + n, and JAX's start-up (precision, where the compilation cache
lives, when there is none)."""

from __future__ import annotations

import errno
import os
import signal
import threading

import pytest

from diffsense.cli import _run
from diffsense.runtime._errors import InputError


def _exit(main, capsys, **kwargs) -> tuple[int, str]:
    with pytest.raises(SystemExit) as e:
        _run.run(main, **kwargs)
    return e.value.code, capsys.readouterr().err


def _raise(error: BaseException):
    def main():
        raise error
    return main


@pytest.mark.parametrize("error, line", [
    (InputError("hfov_deg must be\n  in [0.01, 360]"), "error: hfov_deg must be in [0.01, 360]\n"),
    (PermissionError(errno.EACCES, "Permission denied", "/out/e.json"), "error: /out/e.json: Permission denied\n"),
    (OSError(errno.EXDEV, "Invalid cross-device link", "/a", None, "/b"), "error: /a -> /b: Invalid cross-device link\n"),
    (OSError(errno.ENOSPC, "No space left on device"), "error: [Errno 28] No space left on device\n"),
    (OSError("disk on fire"), "error: disk on fire\n"),
    (OSError(), "error: OSError\n"),
    (FileNotFoundError(errno.ENOENT, "", "/x"), "error: [Errno 2] : '/x'\n"),
])
def test_errors_become_one_line_and_exit_2(capsys, error, line):
    assert _exit(_raise(error), capsys) == (2, line)


def test_a_keyboard_interrupt_that_gets_through_is_one_line_and_130(capsys):
    assert _exit(_raise(KeyboardInterrupt()), capsys) == (130, "interrupted\n")


# A non-zero code first: a run that ended the test process itself (os._exit) would end it with 0.
@pytest.mark.parametrize("returned, code", [(3, 3), (None, 0), (0, 0)])
def test_main_s_code_is_the_exit_code(capsys, returned, code):
    assert _exit(lambda: returned, capsys) == (code, "")


def test_an_entry_point_ends_the_process_with_main_s_code(monkeypatch, capsys):
    ended = []

    def end_now(code):  # os._exit, recorded; SystemExit(-1) marks that it ran
        ended.append(code)
        raise SystemExit(-1)

    monkeypatch.setattr(_run.os, "_exit", end_now)
    assert _exit(lambda: 4, capsys, end_process=True) == (-1, "") and ended == [4]
    assert _exit(lambda: None, capsys, end_process=True) == (-1, "") and ended == [4, 0]
    monkeypatch.setattr(_run, "_distributed", lambda: True)  # a multi-process run leaves normally
    assert _exit(lambda: 5, capsys, end_process=True) == (5, "") and ended == [4, 0]


def test_the_handlers_and_wake_up_pipe_hold_for_the_run_only(capsys):
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    seen = {}

    def main():
        seen.update({s: signal.getsignal(s) for s in before})
        seen["fd"] = signal.set_wakeup_fd(-1)
        signal.set_wakeup_fd(seen["fd"], warn_on_full_buffer=False)
        seen["threads"] = [t.name for t in threading.enumerate()]
        return 0

    assert _exit(main, capsys) == (0, "")
    assert seen[signal.SIGINT] is _run._ignore and seen[signal.SIGTERM] is _run._ignore
    assert seen["fd"] >= 0 and "diffsense-signals" in seen["threads"]
    assert {s: signal.getsignal(s) for s in before} == before
    assert signal.set_wakeup_fd(-1) == -1  # none left set
    assert "diffsense-signals" not in [t.name for t in threading.enumerate()]


def test_off_the_main_thread_main_runs_as_is(capsys):
    seen = []

    def worker():
        with pytest.raises(SystemExit) as e:
            _run.run(lambda: seen.append(signal.getsignal(signal.SIGINT)) or 6)
        seen.append(e.value.code)

    before = signal.getsignal(signal.SIGINT)
    thread = threading.Thread(target=worker)
    thread.start()
    thread.join()
    assert seen == [before, 6]


@pytest.mark.parametrize("signum, line, code", [(signal.SIGINT, b"interrupted\n", 130), (signal.SIGTERM, b"terminated\n", 143)])
def test_a_signal_on_the_pipe_ends_the_process_with_its_line(monkeypatch, signum, line, code):
    read_fd, write_fd = os.pipe()
    os.write(write_fd, bytes([signal.SIGUSR1, signal.SIGCHLD, signum]))
    os.close(write_fd)
    events = []
    monkeypatch.setattr(_run._io, "abandon_temporaries", lambda: events.append("abandoned"))
    monkeypatch.setattr(_run.os, "write", lambda fd, data: events.append((fd, data)))
    monkeypatch.setattr(_run.os, "_exit", lambda c: events.append(c))
    _run._watch(read_fd)  # the patched _exit returns: the watcher reads on to end-of-file
    assert events == ["abandoned", (2, line), code]
    with pytest.raises(OSError):
        os.close(read_fd)  # the watcher closed it


def test_the_line_comes_after_what_the_program_printed_and_a_stuck_flush_does_not_hold_it(monkeypatch):
    events, release = [], threading.Event()

    class Stream:
        def __init__(self, name, stuck=False):
            self.name, self.stuck = name, stuck

        def flush(self):
            if self.stuck:
                release.wait(10)  # a pipe nobody reads
            events.append(f"flushed {self.name}")

    monkeypatch.setattr(_run._io, "abandon_temporaries", lambda: None)
    monkeypatch.setattr(_run.os, "write", lambda fd, data: events.append(data))
    monkeypatch.setattr(_run.os, "_exit", lambda code: events.append(code))
    monkeypatch.setattr(_run.sys, "stdout", Stream("stdout"))
    monkeypatch.setattr(_run.sys, "stderr", Stream("stderr"))
    _run._end(signal.SIGTERM)
    assert events == ["flushed stdout", "flushed stderr", b"terminated\n", 143]
    events.clear()
    monkeypatch.setattr(_run.sys, "stdout", Stream("stdout", stuck=True))
    _run._end(signal.SIGINT)
    assert events == [b"interrupted\n", 130]  # written while the flush still hangs
    release.set()


def test_a_failing_flush_is_ignored(monkeypatch):
    class Broken:
        def flush(self):
            raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(_run.sys, "stdout", Broken())
    monkeypatch.setattr(_run.sys, "stderr", Broken())
    _run._flush_quietly()


@pytest.mark.parametrize("processes, distributed", [(None, False), (1, False), (2, True)])
def test_only_a_run_of_several_processes_counts_as_distributed(monkeypatch, processes, distributed):
    class Jax:
        @staticmethod
        def process_count():
            return processes

    # None: jax never imported (a None entry, not a deletion, which a concurrent import would refill).
    monkeypatch.setitem(_run.sys.modules, "jax", None if processes is None else Jax)
    assert _run._distributed() is distributed


def test_other_signals_on_the_pipe_end_nothing(monkeypatch):
    ends = []
    monkeypatch.setattr(_run, "_end", ends.append)
    read_fd, write_fd = os.pipe()
    os.write(write_fd, bytes([signal.SIGUSR1, signal.SIGWINCH, signal.SIGTERM, signal.SIGINT]))
    os.close(write_fd)
    _run._watch(read_fd)
    assert ends == [signal.SIGTERM, signal.SIGINT]


@pytest.fixture
def configured(monkeypatch):
    """Records what setup_jax sets instead of setting it."""
    import jax

    from diffsense.runtime import _executables

    got = {}
    monkeypatch.setattr(jax.config, "update", lambda name, value: got.__setitem__(name, value))
    monkeypatch.setattr(_executables, "keep_in", lambda folder: got.setdefault("kept", []).append(folder))
    for name in ("JAX_COMPILATION_CACHE_DIR", "XDG_CACHE_HOME", "DIFFSENSE_NO_CACHE"):
        monkeypatch.delenv(name, raising=False)
    return got


def test_the_cache_lives_in_the_user_s_cache_folder(configured, monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    _run.setup_jax()
    assert configured == {
        "jax_enable_x64": True, "jax_compilation_cache_dir": str(tmp_path / "xdg" / "diffsense" / "jax"),
        "jax_persistent_cache_min_compile_time_secs": 0.0, "jax_persistent_cache_min_entry_size_bytes": 0,
        "kept": [None, tmp_path / "xdg" / "diffsense" / "jax" / "executables"]}
    assert (tmp_path / "xdg" / "diffsense" / "jax").is_dir()


def test_without_xdg_the_cache_is_under_home(configured, monkeypatch, tmp_path):
    monkeypatch.setenv("HOME", str(tmp_path))
    _run.setup_jax(float64=False)
    assert configured["jax_enable_x64"] is False
    assert configured["jax_compilation_cache_dir"] == str(tmp_path / ".cache" / "diffsense" / "jax")


def test_jax_compilation_cache_dir_wins(configured, monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", str(tmp_path / "mine"))
    _run.setup_jax()
    assert configured["jax_compilation_cache_dir"] == str(tmp_path / "mine")
    assert configured["kept"] == [None, tmp_path / "mine" / "executables"]
    assert not (tmp_path / "xdg").exists()


@pytest.mark.parametrize("how", ["argument", "environment", "unwritable"])
def test_no_cache_configures_none(configured, monkeypatch, tmp_path, how):
    (tmp_path / "file").write_text("")
    where = tmp_path / "file" / "cache" if how == "unwritable" else tmp_path / "cache"  # under a file, or free
    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", str(where))
    if how == "environment":
        monkeypatch.setenv("DIFFSENSE_NO_CACHE", "1")
    _run.setup_jax(compilation_cache=how != "argument")
    assert configured == {"jax_enable_x64": True, "kept": [None]}
    assert not (tmp_path / "cache").exists()


@pytest.mark.parametrize("value", ["0", "yes", ""])
def test_only_diffsense_no_cache_1_turns_the_cache_off(configured, monkeypatch, tmp_path, value):
    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("DIFFSENSE_NO_CACHE", value)
    _run.setup_jax()
    assert configured["jax_compilation_cache_dir"] == str(tmp_path / "cache")


def test_a_second_start_up_reuses_the_cache_folder(configured, monkeypatch, tmp_path):
    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", str(tmp_path / "cache"))
    (tmp_path / "cache").mkdir()
    _run.setup_jax()
    assert configured["jax_compilation_cache_dir"] == str(tmp_path / "cache")
