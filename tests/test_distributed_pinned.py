"""`diffsense.runtime._distributed` pinned in one process: where `initialize` takes the coordinator, process
count and id from (arguments, then JAX's environment variables), its refusals by whole message,
a second call, the collectives backend it sets, the writer, and `to_host`'s leaves. The join
itself is replaced by a recorder; tests/test_distributed.py joins two real processes."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.runtime._distributed import initialize, is_writer, to_host
from diffsense.runtime._errors import InputError

_VARS = ("JAX_COORDINATOR_ADDRESS", "JAX_NUM_PROCESSES", "JAX_PROCESS_ID")


@pytest.fixture
def joined(monkeypatch):
    """The calls `initialize` makes: [("config", name, value) | ("join", kwargs)]."""
    calls: list = []
    for var in _VARS:
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setattr(jax.distributed, "is_initialized", lambda: False)
    monkeypatch.setattr(jax.distributed, "initialize", lambda **kw: calls.append(("join", kw)))
    update = jax.config.update
    monkeypatch.setattr(jax.config, "update", lambda name, value: calls.append(("config", name, value))
                        if name == "jax_cpu_collectives_implementation" else update(name, value))
    return calls


def _join(**kw) -> tuple:
    return ("join", {"coordinator_address": kw.get("coordinator"), "num_processes": kw.get("n"),
                     "process_id": kw.get("pid")})


def test_arguments_go_to_jax_after_gloo_is_chosen(joined):
    initialize("10.0.0.1:1234", 4, 3)
    assert joined == [("config", "jax_cpu_collectives_implementation", "gloo"),
                      _join(coordinator="10.0.0.1:1234", n=4, pid=3)]


def test_nothing_given_leaves_it_to_jax(joined):
    initialize()
    assert joined[1:] == [_join()]


def test_environment_variables_fill_what_the_arguments_leave(joined, monkeypatch):
    monkeypatch.setenv("JAX_COORDINATOR_ADDRESS", "head:999")
    monkeypatch.setenv("JAX_NUM_PROCESSES", "2")
    monkeypatch.setenv("JAX_PROCESS_ID", "1")
    initialize()
    initialize("given:1", 3, 0)
    initialize(None, 5, None)
    assert [c for c in joined if c[0] == "join"] == [
        _join(coordinator="head:999", n=2, pid=1), _join(coordinator="given:1", n=3, pid=0),
        _join(coordinator="head:999", n=5, pid=1)]
    monkeypatch.setenv("JAX_NUM_PROCESSES", "")  # set but empty: not given
    monkeypatch.setenv("JAX_PROCESS_ID", "")
    joined.clear()
    initialize()
    assert joined[1:] == [_join(coordinator="head:999")]


def test_a_second_call_does_nothing(joined, monkeypatch):
    monkeypatch.setattr(jax.distributed, "is_initialized", lambda: True)
    initialize("10.0.0.1:1234", 0, 5)  # not even checked
    assert joined == []


@pytest.mark.parametrize(("n", "pid", "message"), [
    (0, None, "distributed: the process count must be >= 1, got 0"),
    (-2, 0, "distributed: the process count must be >= 1, got -2"),
    (2, 2, "distributed: process id 2 is not in 0..1"),
    (2, -1, "distributed: process id -1 is not in 0..1"),
    (1, 1, "distributed: process id 1 is not in 0..0"),
])
def test_refusals_by_whole_message(joined, n, pid, message):
    with pytest.raises(InputError) as err:
        initialize("h:1", n, pid)
    assert str(err.value) == message
    assert joined == []  # refused before anything is set


@pytest.mark.parametrize(("n", "pid"), [(1, 0), (2, 1), (1, None), (None, 7)])
def test_the_edges_that_are_accepted(joined, n, pid):
    initialize("h:1", n, pid)
    assert joined[-1] == _join(coordinator="h:1", n=n, pid=pid)


def test_environment_refusals_by_whole_message(joined, monkeypatch):
    monkeypatch.setenv("JAX_NUM_PROCESSES", "two")
    with pytest.raises(InputError) as err:
        initialize()
    assert str(err.value) == "distributed: JAX_NUM_PROCESSES='two' is not an integer"
    monkeypatch.setenv("JAX_NUM_PROCESSES", "2")
    monkeypatch.setenv("JAX_PROCESS_ID", "3")
    with pytest.raises(InputError) as err:
        initialize()
    assert str(err.value) == "distributed: process id 3 is not in 0..1"


@pytest.mark.parametrize("error", [RuntimeError, ValueError])
def test_a_failed_join_is_one_line(joined, monkeypatch, error):
    def refuse(**_):
        raise error("connection refused")

    monkeypatch.setattr(jax.distributed, "initialize", refuse)
    with pytest.raises(InputError) as err:
        initialize("h:1", 2, 0)
    assert str(err.value) == "distributed: cannot join the run: connection refused"
    assert err.value.__cause__ is None and err.value.__suppress_context__


def test_other_failures_are_not_hidden(joined, monkeypatch):
    monkeypatch.setattr(jax.distributed, "initialize", lambda **_: 1 / 0)
    with pytest.raises(ZeroDivisionError):
        initialize("h:1", 2, 0)


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
