"""A command handles SIGINT and SIGTERM from its first moment: the main job interrupted at any
time, while it imports JAX as well as while it computes, exits 130 (SIGTERM 143) with one line and
no traceback, and the previous output set in --out stays as it was, byte for byte. So does a run
that inherits SIGINT ignored, as a shell starts a background job. A library user's process, which
imports diffsense without being a command, keeps its own handlers."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from diffsense import runtime

ROOT = Path(__file__).resolve().parents[1]
JOB = ["--param", "hfov", "--interval", "30", "180", "--scenarios", "sc01", "--variants", "1", "--steps", "30,180"]
ENDINGS = {signal.SIGINT: ("interrupted", 130), signal.SIGTERM: ("terminated", 143)}
# Starts the command with SIGINT's disposition set (ignored or default) whatever this process's
# is, as a shell does for a job it starts: exec keeps an ignored signal ignored.
LAUNCH = ("import os, signal, sys; signal.signal(signal.SIGINT, getattr(signal, sys.argv[1])); "
          "os.execv(sys.argv[2], sys.argv[2:])")


def _previous_set(out: Path) -> None:
    with runtime.output_set(out) as staging:
        runtime.write_json(staging / "result.json", {"run": "previous"})
        runtime.write_bytes(staging / "radar" / "objective.png", b"\x89PNG previous")
    (out / "notes.txt").write_text("the user's own file")


def _everything(folder: Path) -> dict[str, bytes | None]:
    """Every entry under `folder`, hidden ones too: a file's bytes, None for a folder."""
    return {p.relative_to(folder).as_posix(): None if p.is_dir() else p.read_bytes() for p in folder.rglob("*")}


def _interrupt(command: list[str], inherited: str, signum: int, at_s: float) -> tuple[int, str]:
    start = time.monotonic()
    proc = subprocess.Popen([sys.executable, "-c", LAUNCH, inherited, *command], cwd=ROOT, text=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
    time.sleep(max(0.0, start + at_s - time.monotonic()))
    proc.send_signal(signum)
    try:
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    return proc.returncode, err


CASES = [(signal.SIGINT, at_s, "SIG_IGN") for at_s in (0.3, 1.0, 2.0, 5.0)] + [
    (signal.SIGINT, 0.3, "SIG_DFL"), (signal.SIGINT, 2.0, "SIG_DFL"), (signal.SIGTERM, 1.0, "SIG_DFL")]


@pytest.mark.parametrize("signum, at_s, inherited", CASES,
                         ids=[f"{s.name}-{t}s-{i.lower()}" for s, t, i in CASES])
def test_the_main_job_interrupted_at_any_moment_keeps_the_previous_set(tmp_path, signum, at_s, inherited):
    out = tmp_path / "out"
    _previous_set(out)
    before = _everything(out)
    code, err = _interrupt([sys.executable, "-m", "diffsense.optimise", *JOB, "--out", str(out)],
                           inherited, signum, at_s)
    line, expected = ENDINGS[signum]
    assert code == expected, err[-2000:]
    assert "Traceback" not in err and err.splitlines()[-1:] == [line], err[-2000:]
    assert _everything(out) == before


@pytest.mark.parametrize("script, command", [("diffsense", ["optimise"]), ("diffsense-optimise", [])])
def test_the_console_scripts_interrupted_while_they_start_keep_the_previous_set(tmp_path, script, command):
    path = shutil.which(script, path=os.path.dirname(sys.executable))
    if path is None:
        pytest.skip("the console scripts are not installed (pip install -e .)")
    out = tmp_path / "out"
    _previous_set(out)
    before = _everything(out)
    code, err = _interrupt([path, *command, *JOB, "--out", str(out)], "SIG_IGN", signal.SIGINT, 0.5)
    assert (code, "Traceback" in err, err.splitlines()[-1:]) == (130, False, ["interrupted"]), err[-2000:]
    assert _everything(out) == before


def test_a_library_user_keeps_its_own_handlers():
    probe = "import signal, diffsense; print(signal.getsignal(signal.SIGINT) is signal.default_int_handler)"
    done = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert done.stdout == "True\n", done.stderr[-2000:]
