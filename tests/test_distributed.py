"""More than one host, for real: two CPU processes on localhost (gloo collectives) give the same E
and gradient as one process; the command line's --distributed run writes one set of outputs."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = """
import json, sys, jax
jax.config.update("jax_enable_x64", True)
from diffsense.runtime._distributed import initialize
pid, n, address = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
if n > 1:
    initialize(address, n, pid)
from diffsense.solve import Evaluator
from tests._toy_pipeline import toy_objective
ev = Evaluator(toy_objective(n=3))  # 3 variants over 2 processes: one padding row
value, grad = ev.value_and_grad(42.0)
rows = ev.hard(42.0).sq_error  # [N, F] split over the processes: gathered whole, in order
print(json.dumps({"processes": jax.process_count(), "devices": len(jax.devices()), "e2": float(value),
                  "grad": float(grad[0]), "hard": ev.e_hard(42.0), "rows": len(rows), "sq_error": rows[:3].tolist()}))
"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def _env() -> dict:
    env = dict(os.environ, JAX_PLATFORMS="cpu", PYTHONPATH=str(ROOT), DIFFSENSE_NO_CACHE="1")
    env.pop("XLA_FLAGS", None)
    return env


def _launch(args_of, n: int) -> list[subprocess.CompletedProcess]:
    procs = [subprocess.Popen(args_of(i), cwd=ROOT, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True) for i in range(n)]
    return [subprocess.CompletedProcess(p.args, p.wait(timeout=600), *p.communicate()) for p in procs]


def test_two_processes_match_one():
    address = f"localhost:{_free_port()}"
    runs = _launch(lambda i: [sys.executable, "-c", SCRIPT, str(i), "2", address], 2)
    one = _launch(lambda i: [sys.executable, "-c", SCRIPT, "0", "1", "-"], 1)[0]
    for r in runs + [one]:
        assert r.returncode == 0, r.stderr[-2000:]
    two = [json.loads(r.stdout.strip().splitlines()[-1]) for r in runs]
    single = json.loads(one.stdout.strip().splitlines()[-1])
    assert single["processes"] == 1 and all(t["processes"] == 2 and t["devices"] == 2 for t in two)
    for t in two:
        for key in ("e2", "grad", "hard"):
            assert t[key] == pytest.approx(single[key], rel=1e-6, abs=1e-9), key
        assert t["rows"] == 4 and single["rows"] == 3  # one zero-weight padding row over 2 devices
        np.testing.assert_allclose(t["sq_error"], single["sq_error"], rtol=1e-6, atol=1e-9)


@pytest.mark.slow
def test_cli_distributed_run_writes_one_set(tmp_path):
    address = f"localhost:{_free_port()}"
    common = ["-m", "diffsense.optimise", "--param", "hfov", "--interval", "30", "180", "--scenarios", "sc01",
              "--variants", "3", "--steps", "30,180", "--quiet"]
    runs = _launch(lambda i: [sys.executable, *common, "--out", str(tmp_path / "two"), "--distributed",
                              "--coordinator", address, "--num-processes", "2", "--process-id", str(i)], 2)
    one = _launch(lambda i: [sys.executable, *common, "--out", str(tmp_path / "one")], 1)[0]
    for r in runs + [one]:
        assert r.returncode == 0, r.stderr[-2000:]
    # process 1 prints no summary (gloo itself logs its connection on stdout)
    assert "pooled" in runs[0].stdout and "pooled" not in runs[1].stdout and "radar:" not in runs[1].stdout
    a = json.loads((tmp_path / "one" / "result.json").read_text())
    b = json.loads((tmp_path / "two" / "result.json").read_text())
    assert b["r_star"]["hfov_deg"] == pytest.approx(a["r_star"]["hfov_deg"], rel=1e-9)
    assert b["E_hard_star"] == pytest.approx(a["E_hard_star"], rel=1e-9)


def test_distributed_flags_need_distributed(tmp_path):
    r = subprocess.run([sys.executable, "-m", "diffsense.optimise", "--process-id", "1", "--out", str(tmp_path / "o")],
                       cwd=ROOT, env=_env(), capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and r.stderr.strip().splitlines()[-1].startswith("error:")
    assert not (tmp_path / "o").exists()
