"""A distributed run whose processes cannot all join ends within the join timeout
(DIFFSENSE_JOIN_TIMEOUT_S) with one `error:` line naming the coordinator and exit code 2, and
writes nothing: a refused port, an address that does not answer, and process 0 whose peer never
comes. Without the bound, JAX's client waits 300 s and then aborts the process with a C++ stack."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TIMEOUT_S = 1


def _closed_port() -> int:
    """A port that was just bound and closed: nothing listens there."""
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def _join(tmp_path: Path, coordinator: str, process_id: int) -> tuple[subprocess.CompletedProcess, float]:
    env = dict(os.environ, JAX_PLATFORMS="cpu", PYTHONPATH=str(ROOT), DIFFSENSE_NO_CACHE="1",
               DIFFSENSE_JOIN_TIMEOUT_S=str(TIMEOUT_S))
    env.pop("XLA_FLAGS", None)
    args = [sys.executable, "-m", "diffsense.optimise", "--param", "hfov", "--interval", "30", "180",
            "--scenarios", "sc01", "--variants", "2", "--steps", "30,180", "--quiet", "--out", str(tmp_path / "out"),
            "--distributed", "--coordinator", coordinator, "--num-processes", "2", "--process-id", str(process_id)]
    start = time.monotonic()
    run = subprocess.run(args, cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    return run, time.monotonic() - start


@pytest.mark.parametrize(("coordinator", "process_id"), [
    pytest.param(f"localhost:{_closed_port()}", 1, id="refused port"),
    pytest.param("192.0.2.1:1234", 1, id="unreachable address"),  # TEST-NET-1: routed nowhere
    pytest.param(f"localhost:{_closed_port()}", 0, id="process 0 without its peer"),
])
def test_a_join_that_cannot_form_ends_in_one_error_line(tmp_path, coordinator, process_id):
    run, seconds = _join(tmp_path, coordinator, process_id)
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2, run.stderr[-2000:]
    assert len(lines) == 1 and lines[0].startswith("error:") and coordinator in lines[0], run.stderr[-2000:]
    assert "DIFFSENSE_JOIN_TIMEOUT_S" in lines[0]  # says how to wait longer
    assert not (tmp_path / "out").exists()
    # start-up (imports, the problem built) takes a few seconds; the join adds at most its timeout
    assert seconds < 60
