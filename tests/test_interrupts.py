"""Interrupts, signals and output folders: `run(main)` ends on SIGINT/SIGTERM with one line and
exit 130/143 even inside a JAX host callback, leaving no temporary behind; output sets replace
each other whole; unwritable output folders are refused before any work; files get the umask's
mode."""

from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import diffsense as ds
from diffsense import runtime

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = "manifest.json"

# A CLI whose main prints "ready" on stdout, then waits: in a host callback, in plain Python, in
# the middle of an output set, or in the middle of one atomic file.
SCRIPT = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    sys.path.insert(0, sys.argv[3])  # the package under test
    from diffsense import runtime
    from diffsense.cli import run

    mode, folder = sys.argv[1], Path(sys.argv[2])

    def ready():
        print("ready", flush=True)
        time.sleep(60)

    def main():
        if mode == "callback":
            import jax, jax.numpy as jnp
            spec = jax.ShapeDtypeStruct((), jnp.float32)
            f = jax.jit(lambda x: jax.pure_callback(lambda v: (ready(), v)[1], spec, x))
            f(jnp.float32(1.0)).block_until_ready()
        elif mode == "python":
            ready()
        elif mode == "set":
            with runtime.output_set(folder) as staging:
                runtime.write_json(staging / "result.json", {"run": 2})
                with runtime.atomic_open(staging / "sub" / "fig.png") as f:
                    f.write(b"half a figure")
                    ready()
        elif mode == "file":
            with runtime.atomic_open(folder / "data.bin") as f:
                f.write(b"half")
                ready()

    run(main)
    """
)


def _start(tmp_path: Path, mode: str, folder: Path) -> subprocess.Popen:
    script = tmp_path / "cli.py"
    script.write_text(SCRIPT)
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    return subprocess.Popen([sys.executable, str(script), mode, str(folder), str(ROOT)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)


def _signal_when_ready(proc: subprocess.Popen, signum: int) -> tuple[int, str]:
    line = proc.stdout.readline()
    assert line == "ready\n", f"child not ready: {line!r} {proc.communicate(timeout=60)[1][-2000:]}"
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=20)
    return proc.returncode, err


def _tree(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("mode", ["callback", "python"])
def test_sigint_and_sigterm_end_with_one_line(tmp_path, mode):
    procs = {s: _start(tmp_path, mode, tmp_path) for s in (signal.SIGINT, signal.SIGTERM)}
    for signum, (code, line) in {signal.SIGINT: (130, "interrupted"), signal.SIGTERM: (143, "terminated")}.items():
        rc, err = _signal_when_ready(procs[signum], signum)
        assert (rc, err) == (code, line + "\n"), err[-2000:]


def test_interrupted_set_leaves_the_previous_set_and_no_temporary(tmp_path):
    out = tmp_path / "out"
    with runtime.output_set(out) as staging:
        runtime.write_json(staging / "result.json", {"run": 1})
        (staging / "old.txt").write_text("first run")
    before = _tree(out)
    procs = [(_start(tmp_path, "set", out), signal.SIGINT), (_start(tmp_path, "file", tmp_path / "f"), signal.SIGTERM)]
    assert [_signal_when_ready(p, s)[0] for p, s in procs] == [130, 143]
    assert _tree(out) == before
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json", "old.txt", "result.json"]
    assert list((tmp_path / "f").iterdir()) == []


def test_a_completed_set_replaces_the_previous_set_whole(tmp_path):
    out = tmp_path / "a" / "out"
    with runtime.output_set(out) as staging:
        runtime.write_json(staging / "result.json", {"run": 1})
        runtime.write_bytes(staging / "radar" / "fig.png", b"radar")
        runtime.write_bytes(staging / "old.txt", b"only in run 1")
    (out / "notes.txt").write_text("the user's own file")
    with runtime.output_set(out) as staging:
        runtime.write_json(staging / "result.json", {"run": 2})
        runtime.write_bytes(staging / "camera" / "fig.png", b"camera")
    assert _tree(out).keys() == {"camera/fig.png", "manifest.json", "notes.txt", "result.json"}
    assert json.loads((out / "result.json").read_text()) == {"run": 2}
    assert json.loads((out / MANIFEST).read_text())["files"] == ["camera/fig.png", "result.json"]
    assert not (out / "radar").exists()  # emptied by the replacement, so removed
    assert not list(out.glob(".staging-*"))


def test_a_failed_set_changes_nothing(tmp_path):
    out = tmp_path / "new" / "out"
    with pytest.raises(RuntimeError), runtime.output_set(out) as staging:
        runtime.write_bytes(staging / "x.txt", b"x")
        raise RuntimeError("solver failed")
    assert not (tmp_path / "new").exists()  # the folders the set created are gone with it
    out.mkdir(parents=True)
    (out / "result.json").mkdir()  # a folder in the way: refused before anything moves
    with pytest.raises(ds.InputError, match="in the way"), runtime.output_set(out) as staging:
        runtime.write_bytes(staging / "result.json", b"{}")
    assert [p.name for p in out.iterdir()] == ["result.json"]


def test_check_writable(tmp_path):
    runtime.check_writable(tmp_path / "new" / "deeper")  # creatable: fine, and nothing is created
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "file.txt").write_text("x")
    for bad, needle in ((tmp_path / "file.txt", "not a folder"), (tmp_path / "file.txt" / "out", "not a folder")):
        with pytest.raises(ds.InputError, match=needle) as info:
            runtime.check_writable(bad)
        assert "\n" not in str(info.value)
    if Path("/proc/self").is_dir():  # read-only for root too
        with pytest.raises(ds.InputError, match="not writable"):
            runtime.check_writable("/proc/diffsense-out")
    if os.geteuid() != 0:  # root ignores permission bits
        locked = tmp_path / "locked"
        locked.mkdir(mode=0o555)
        with pytest.raises(ds.InputError, match="not writable"):
            runtime.check_writable(locked / "out")


@pytest.mark.parametrize("umask", [0o022, 0o077, 0o002])
def test_files_get_the_umask_mode(tmp_path, umask):
    old = os.umask(umask)
    try:
        runtime.write_bytes(tmp_path / "plain.bin", b"x")
        with runtime.output_set(tmp_path / "out") as staging:
            runtime.write_bytes(staging / "set.bin", b"y")
    finally:
        os.umask(old)
    for path in (tmp_path / "plain.bin", tmp_path / "out" / "set.bin", tmp_path / "out" / MANIFEST):
        assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~umask, path
