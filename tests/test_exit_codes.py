"""The exit-code contract of `diffsense.cli.run`, which every face runs its main under: an
InputError or OSError is one `error:` line naming the culprit and exit 2, main's code is the exit
code, the signal handlers hold for the run only, an entry point ends with its output flushed; and
where `setup_jax` keeps the compilation cache (JAX_COMPILATION_CACHE_DIR, XDG_CACHE_HOME, ~/.cache;
none under DIFFSENSE_NO_CACHE=1 or an unwritable folder)."""

from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import jax
import pytest

import diffsense as ds
from diffsense import runtime
from diffsense.cli import run, setup_jax

ROOT = Path(__file__).resolve().parents[1]


def _exit(main, capsys) -> tuple[int, str]:
    with pytest.raises(SystemExit) as e:
        run(main)
    return e.value.code, capsys.readouterr().err


def _raise(error: BaseException):
    def main():
        raise error
    return main


@pytest.mark.parametrize("error, line", [
    (ds.InputError("hfov_deg must be\n  in [0.01, 360]"), "error: hfov_deg must be in [0.01, 360]\n"),
    (PermissionError(errno.EACCES, "Permission denied", "/out/e.json"), "error: /out/e.json: Permission denied\n"),
    (OSError(errno.EXDEV, "Invalid cross-device link", "/a", None, "/b"), "error: /a -> /b: Invalid cross-device link\n"),
    (OSError(errno.ENOSPC, "No space left on device"), "error: [Errno 28] No space left on device\n"),
    (OSError(), "error: OSError\n"),
])
def test_bad_input_and_os_errors_are_one_line_and_exit_2(capsys, error, line):
    assert _exit(_raise(error), capsys) == (2, line)


def test_a_keyboard_interrupt_that_gets_through_is_one_line_and_130(capsys):
    assert _exit(_raise(KeyboardInterrupt()), capsys) == (130, "interrupted\n")


@pytest.mark.parametrize("returned, code", [(3, 3), (None, 0), (0, 0)])
def test_main_s_code_is_the_exit_code(capsys, returned, code):
    assert _exit(lambda: returned, capsys) == (code, "")


def test_the_signal_handlers_hold_for_the_run_only(capsys):
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    seen = {}

    def main():
        seen.update({s: signal.getsignal(s) for s in before})
        return 0

    assert _exit(main, capsys) == (0, "")
    assert all(seen[s] is not before[s] for s in before)  # run's own, during the run
    assert {s: signal.getsignal(s) for s in before} == before
    assert signal.set_wakeup_fd(-1) == -1  # no wake-up pipe left set


def test_an_entry_point_ends_at_once_with_its_code_and_its_output_flushed(tmp_path):
    """`run(main, end_process=True)` skips the interpreter's teardown: what main printed, even
    unflushed, still arrives, and the exit code is main's."""
    script = tmp_path / "entry.py"
    script.write_text(textwrap.dedent("""
        import atexit, sys
        from diffsense.cli import run
        atexit.register(lambda: print("teardown ran"))
        def main():
            print("printed " * 2000)  # more than one buffer, on a pipe
            sys.stderr.write("to stderr")
            return 3
        run(main, end_process=True)
    """))
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert proc.returncode == 3
    assert proc.stdout.strip() == ("printed " * 2000).strip()  # all of it, and no teardown line
    assert proc.stderr == "to stderr"


@pytest.fixture
def configured(monkeypatch):
    """What setup_jax sets, recorded instead of set."""
    got = {}
    monkeypatch.setattr(jax.config, "update", lambda name, value: got.__setitem__(name, value))
    monkeypatch.setattr(runtime, "keep_in", lambda folder: got.setdefault("kept", []).append(folder))
    for name in ("JAX_COMPILATION_CACHE_DIR", "XDG_CACHE_HOME", "DIFFSENSE_NO_CACHE"):
        monkeypatch.delenv(name, raising=False)
    return got


@pytest.mark.parametrize("env, folder", [
    ({"XDG_CACHE_HOME": "xdg"}, "xdg/diffsense/jax"),
    ({"HOME": "."}, ".cache/diffsense/jax"),
    ({"XDG_CACHE_HOME": "xdg", "JAX_COMPILATION_CACHE_DIR": "mine"}, "mine"),
    ({"JAX_COMPILATION_CACHE_DIR": "mine", "DIFFSENSE_NO_CACHE": "0"}, "mine"),  # only "1" turns it off
])
def test_where_the_compilation_cache_lives(configured, monkeypatch, tmp_path, env, folder):
    for name, value in env.items():
        monkeypatch.setenv(name, str(tmp_path / value) if name != "DIFFSENSE_NO_CACHE" else value)
    setup_jax(float64=False)
    cache = tmp_path / folder
    assert configured == {"jax_enable_x64": False, "jax_compilation_cache_dir": str(cache),
                          "jax_persistent_cache_min_compile_time_secs": 0.0,
                          "jax_persistent_cache_min_entry_size_bytes": 0, "kept": [None, cache / "executables"]}
    assert cache.is_dir() and sorted(p.name for p in tmp_path.iterdir()) == [Path(folder).parts[0]]


@pytest.mark.parametrize("how", ["argument", "environment", "unwritable"])
def test_no_cache_configures_none(configured, monkeypatch, tmp_path, how):
    (tmp_path / "file").write_text("")
    where = tmp_path / "file" / "cache" if how == "unwritable" else tmp_path / "cache"  # under a file, or free
    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", str(where))
    if how == "environment":
        monkeypatch.setenv("DIFFSENSE_NO_CACHE", "1")
    setup_jax(compilation_cache=how != "argument")
    assert configured == {"jax_enable_x64": True, "kept": [None]}
    assert not (tmp_path / "cache").exists()
