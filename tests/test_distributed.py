"""More than one host: two CPU processes on localhost (gloo collectives) give the same E and
gradient as one process; the command line's --distributed run writes one set of outputs; and, in
one process with the join replaced by a recorder, where `initialize` takes the coordinator,
process count and id from (arguments, then JAX's environment variables), what it refuses, the
collectives backend it sets, the writer, and `to_host`'s leaves."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.runtime import InputError, initialize, is_writer, to_host

ROOT = Path(__file__).resolve().parents[1]
_VARS = ("JAX_COORDINATOR_ADDRESS", "JAX_NUM_PROCESSES", "JAX_PROCESS_ID")

SCRIPT = """
import json, sys, jax
jax.config.update("jax_enable_x64", True)
from diffsense.runtime import initialize
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


@pytest.fixture
def joined(monkeypatch):
    """The calls `initialize` makes: [("config", name, value) | ("join", kwargs)]."""
    calls: list = []
    for var in (*_VARS, "DIFFSENSE_JOIN_TIMEOUT_S"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setattr(jax.distributed, "is_initialized", lambda: False)
    monkeypatch.setattr(jax.distributed, "initialize", lambda **kw: calls.append(("join", kw)))
    update = jax.config.update
    monkeypatch.setattr(jax.config, "update", lambda name, value: calls.append(("config", name, value))
                        if name == "jax_cpu_collectives_implementation" else update(name, value))
    return calls


@pytest.fixture
def head():
    """HOST:PORT of a coordinator that is listening (what a process other than 0 connects to)."""
    with socket.create_server(("localhost", 0)) as server:
        yield f"localhost:{server.getsockname()[1]}"


@pytest.fixture
def free() -> str:
    """HOST:PORT with a free port on this host (what process 0 serves the coordinator on)."""
    return f"localhost:{_free_port()}"


def _join(coordinator=None, n=None, pid=None) -> tuple:
    return ("join", {"coordinator_address": coordinator, "num_processes": n, "process_id": pid})


def _joins(calls: list) -> list:
    """The joins, each with the three arguments that say who joins where."""
    keys = ("coordinator_address", "num_processes", "process_id")
    return [("join", {k: c[1][k] for k in keys}) for c in calls if c[0] == "join"]


def test_arguments_go_to_jax_after_gloo_is_chosen(joined, head):
    initialize(head, 4, 3)
    initialize()  # nothing given: left to JAX (a cluster scheduler it detects)
    assert [c if c[0] == "config" else _joins([c])[0] for c in joined] == [
        ("config", "jax_cpu_collectives_implementation", "gloo"), _join(head, 4, 3),
        ("config", "jax_cpu_collectives_implementation", "gloo"), _join()]


def test_environment_variables_fill_what_the_arguments_leave(joined, monkeypatch, head, free):
    monkeypatch.setenv("JAX_COORDINATOR_ADDRESS", head)
    monkeypatch.setenv("JAX_NUM_PROCESSES", "2")
    monkeypatch.setenv("JAX_PROCESS_ID", "1")
    initialize()
    initialize(free, 3, 0)
    initialize(None, 5, None)
    monkeypatch.setenv("JAX_NUM_PROCESSES", "")  # set but empty: not given
    monkeypatch.setenv("JAX_PROCESS_ID", "")
    initialize()
    assert _joins(joined) == [_join(head, 2, 1), _join(free, 3, 0), _join(head, 5, 1), _join(head)]


def test_a_second_call_does_nothing(joined, monkeypatch):
    monkeypatch.setattr(jax.distributed, "is_initialized", lambda: True)
    initialize("10.0.0.1:1234", 0, 5)  # not even checked
    assert joined == []


@pytest.mark.parametrize(("n", "pid", "culprit"), [
    (0, None, "process count"), (-2, 0, "process count"), (2, 2, "process id 2"), (2, -1, "process id -1"),
    (1, 1, "process id 1"),
])
def test_a_process_count_below_one_or_an_id_outside_it_is_refused(joined, n, pid, culprit):
    with pytest.raises(InputError, match=culprit):
        initialize("h:1", n, pid)
    assert joined == []  # refused before anything is set


@pytest.mark.parametrize(("n", "pid"), [(1, 0), (2, 1), (1, None), (None, 7)])
def test_the_edges_that_are_accepted(joined, n, pid, head, free):
    address = free if pid == 0 else head
    initialize(address, n, pid)
    assert _joins(joined)[-1] == _join(address, n, pid)


def test_bad_environment_variables_are_refused(joined, monkeypatch):
    monkeypatch.setenv("JAX_NUM_PROCESSES", "two")
    with pytest.raises(InputError, match="JAX_NUM_PROCESSES"):
        initialize()
    monkeypatch.setenv("JAX_NUM_PROCESSES", "2")
    monkeypatch.setenv("JAX_PROCESS_ID", "3")
    with pytest.raises(InputError, match="process id 3"):
        initialize()


@pytest.mark.parametrize("error", [RuntimeError, ValueError])
def test_a_failed_join_is_one_input_error(joined, monkeypatch, error, free):
    def refuse(**_):
        raise error("connection refused")

    monkeypatch.setattr(jax.distributed, "initialize", refuse)
    with pytest.raises(InputError, match="connection refused") as err:
        initialize(free, 2, 0)
    assert err.value.__cause__ is None and err.value.__suppress_context__


@pytest.mark.parametrize(("env", "argument"), [("0", None), ("-1", None), ("nan", None), ("inf", None),
                                             ("soon", None), (None, 0.0), (None, float("nan")), ("5", -1)])
def test_a_join_timeout_that_is_not_a_positive_number_is_refused(joined, monkeypatch, head, env, argument):
    if env is not None:
        monkeypatch.setenv("DIFFSENSE_JOIN_TIMEOUT_S", env)
    with pytest.raises(InputError, match="join_timeout_s" if argument is not None else "DIFFSENSE_JOIN_TIMEOUT_S"):
        initialize(head, 2, 1, join_timeout_s=argument)
    assert joined == []


def test_jax_own_join_timeout_lies_beyond_ours(joined, monkeypatch, head):
    initialize(head, 2, 1)  # the documented default, 60 s
    monkeypatch.setenv("DIFFSENSE_JOIN_TIMEOUT_S", "90")
    initialize(head, 2, 1)
    initialize(head, 2, 1, join_timeout_s=120)  # the argument before the variable
    assert [c[1]["initialization_timeout"] > t for c, t in zip(joined[1::2], (60, 90, 120), strict=True)] == [True] * 3


@pytest.mark.parametrize("case", ["refused", "unresolvable", "port taken", "not this host"])
def test_a_coordinator_out_of_reach_is_refused_within_the_timeout(joined, head, case):
    address, pid = {"refused": (f"localhost:{_free_port()}", 1), "unresolvable": ("no-such-host.invalid:1234", 1),
                    "port taken": (head, 0), "not this host": ("192.0.2.1:1234", 0)}[case]
    start = time.monotonic()
    with pytest.raises(InputError, match=address):
        initialize(address, 2, pid, join_timeout_s=0.5)
    assert time.monotonic() - start < 5 and joined == []


def test_process_0_writes(monkeypatch):
    assert is_writer()
    monkeypatch.setattr(jax, "process_index", lambda: 1)
    assert not is_writer()


@pytest.mark.parametrize("processes", [1, 2])
def test_to_host_gives_numpy_leaves_with_every_value(monkeypatch, processes):
    monkeypatch.setattr(jax, "process_count", lambda: processes)
    tree = {"e2": jnp.asarray(2.5), "grad": (jnp.arange(3.0), 4.0), "n": 3}
    host = to_host(tree)
    assert jax.tree.structure(host) == jax.tree.structure(tree)
    assert all(type(leaf) is np.ndarray for leaf in jax.tree.leaves(host))
    np.testing.assert_array_equal(host["grad"][0], [0.0, 1.0, 2.0])
    assert float(host["e2"]) == 2.5 and float(host["grad"][1]) == 4.0 and int(host["n"]) == 3
