"""More than one host: every process runs the same program on its share of the scene variants.

The variants are sharded over `jax.devices()` (`diffsense.metrics._sharding`), which after
`initialize` spans every device of every process; each process simulates all scenes (same seed,
same scenes) and feeds its own devices' share. E and its gradient are sums over variants, reduced
by XLA's collectives across processes (gloo on CPU hosts). Values the host reads back are gathered
from every process (`to_host`), so the solver takes the same steps everywhere; only process 0
writes outputs.

The coordinator, process count and id come from the arguments, else from JAX's own environment
variables (JAX_COORDINATOR_ADDRESS, JAX_NUM_PROCESSES, JAX_PROCESS_ID), else from the cluster
scheduler JAX detects (Slurm, Open MPI).

The join is bounded by `join_timeout_s` (else DIFFSENSE_JOIN_TIMEOUT_S, else 60 s). JAX's own
client ends the process with SIGABRT and a C++ stack when its join fails, so it never gets that
far: with the coordinator, count and id known, a process other than 0 first connects to the
coordinator over TCP (retried until the deadline), and process 0 first checks that it can listen
on the port and that the address reaches this host; each failure is an `InputError`. A join that
still has not formed at the deadline (process 0 waiting for a peer that never comes) ends the
process with the line `error: ...` on stderr and exit code 2, before JAX's timeout fires.
"""

from __future__ import annotations

import math
import os
import socket
import sys
import threading
import time
from typing import Any

import jax
import numpy as np

from diffsense.runtime._errors import InputError

_ENV = {"coordinator": "JAX_COORDINATOR_ADDRESS", "num_processes": "JAX_NUM_PROCESSES", "process_id": "JAX_PROCESS_ID"}
JOIN_TIMEOUT_ENV = "DIFFSENSE_JOIN_TIMEOUT_S"
DEFAULT_JOIN_TIMEOUT_S = 60.0
_JAX_MARGIN_S = 30  # JAX's own timeout lies this far beyond ours, so ours always ends the join first
_RETRY_S = 0.25


def initialize(coordinator: str | None = None, num_processes: int | None = None, process_id: int | None = None,
               join_timeout_s: float | None = None) -> None:
    """Join the run's processes (call before any JAX computation; a second call does nothing).

    Raises `InputError` for a bad address, count, id or timeout and for a coordinator that cannot
    be reached within the timeout; ends the process (exit 2, one `error:` line) if the processes
    have not all joined by then.
    """
    if jax.distributed.is_initialized():
        return
    given = {"coordinator": coordinator, "num_processes": num_processes, "process_id": process_id}
    for name, var in _ENV.items():
        if given[name] is None and os.environ.get(var):
            given[name] = os.environ[var] if name == "coordinator" else _int(var, os.environ[var])
    address = _parse_address(given["coordinator"]) if given["coordinator"] is not None else None
    n, pid = given["num_processes"], given["process_id"]
    if n is not None and n < 1:
        raise InputError(f"distributed: the process count must be >= 1, got {n}")
    if pid is not None and n is not None and not 0 <= pid < n:
        raise InputError(f"distributed: process id {pid} is not in 0..{n - 1}")
    timeout = _join_timeout(join_timeout_s)
    deadline = time.monotonic() + timeout
    if address is not None and pid is not None:
        (_check_coordinator_port if pid == 0 else _reach_coordinator)(address, given["coordinator"], timeout, deadline)
    # CPU hosts need a collectives backend for cross-process reductions; GPU/TPU bring their own.
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    where = f"at the coordinator {given['coordinator']}" if address else "(coordinator from the cluster scheduler)"
    joined = _end_process_at(deadline, f"distributed: the run's {f'{n} ' if n else ''}processes did not all join {where} within "
                                       f"{timeout:g} s (set {JOIN_TIMEOUT_ENV} to wait longer)")
    try:
        jax.distributed.initialize(coordinator_address=given["coordinator"], num_processes=n, process_id=pid,
                                   initialization_timeout=math.ceil(timeout) + _JAX_MARGIN_S)
    except (RuntimeError, ValueError) as e:
        raise InputError(f"distributed: cannot join the run: {e}") from None
    finally:
        joined.set()


def _parse_address(address: str) -> tuple[str, int]:
    """(host, port) of HOST:PORT (an IPv6 host in brackets) with a port in 1..65535."""
    host, sep, port = address.rpartition(":")
    if not sep or not host or not port.isdigit() or not 1 <= int(port) <= 65535:
        raise InputError(f"distributed: the coordinator address must be HOST:PORT with a port in 1..65535, "
                         f"got {address[:80]!r}")
    return host.removeprefix("[").removesuffix("]"), int(port)


def _join_timeout(value: float | None) -> float:
    what = "join_timeout_s" if value is not None else JOIN_TIMEOUT_ENV
    text = value if value is not None else os.environ.get(JOIN_TIMEOUT_ENV) or DEFAULT_JOIN_TIMEOUT_S
    try:
        seconds = float(text)
    except (TypeError, ValueError):
        seconds = math.nan
    if not (math.isfinite(seconds) and seconds > 0):
        raise InputError(f"distributed: {what} must be a positive number of seconds, got {str(text)[:80]!r}")
    return seconds


def _reach_coordinator(address: tuple[str, int], shown: str, timeout: float, deadline: float) -> None:
    """Return once a TCP connection to the coordinator succeeds; InputError at the deadline."""
    last = "no answer"
    while (left := deadline - time.monotonic()) > 0:
        try:
            socket.create_connection(address, timeout=left).close()
            return
        except socket.gaierror as e:
            raise InputError(f"distributed: cannot resolve the coordinator host of {shown}: {e.strerror}") from None
        except TimeoutError:
            last = "no answer"
        except OSError as e:
            last = e.strerror or type(e).__name__
            time.sleep(min(_RETRY_S, max(0.0, deadline - time.monotonic())))
    raise InputError(f"distributed: cannot reach the coordinator {shown} within {timeout:g} s ({last}; "
                     f"is process 0 running? set {JOIN_TIMEOUT_ENV} to wait longer)")


def _check_coordinator_port(address: tuple[str, int], shown: str, timeout: float, deadline: float) -> None:
    """Process 0 serves the coordinator on every interface: InputError unless the port is free
    here and the address leads back to this host."""
    port = address[1]
    try:
        dual = socket.has_dualstack_ipv6()
        server = socket.create_server(("", port), family=socket.AF_INET6 if dual else socket.AF_INET,
                                      dualstack_ipv6=dual)
    except OSError as e:
        raise InputError(f"distributed: process 0 cannot serve the coordinator {shown}: port {port}: "
                         f"{e.strerror}") from None
    with server:
        try:
            socket.create_connection(address, timeout=max(0.1, deadline - time.monotonic())).close()
        except socket.gaierror as e:
            raise InputError(f"distributed: cannot resolve the coordinator host of {shown}: {e.strerror}") from None
        except TimeoutError:
            raise InputError(f"distributed: the coordinator address {shown} does not lead to this host, process 0, "
                             f"which serves the coordinator (no answer within {timeout:g} s)") from None
        except OSError as e:
            raise InputError(f"distributed: the coordinator address {shown} does not lead to this host, process 0, "
                             f"which serves the coordinator ({e.strerror or type(e).__name__})") from None


def _end_process_at(deadline: float, message: str) -> threading.Event:
    """An event to set once the join is done; unless set by the deadline, the process ends with
    `error: message` and exit code 2 (the join blocks in C++, where no exception reaches it)."""
    done = threading.Event()

    def watch() -> None:
        if done.wait(max(0.0, deadline - time.monotonic())):
            return
        try:
            sys.stdout.flush()
        finally:
            os.write(2, f"error: {message}\n".encode())
            os._exit(2)

    threading.Thread(target=watch, name="diffsense-join-deadline", daemon=True).start()
    return done


def _int(var: str, text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise InputError(f"distributed: {var}={text!r} is not an integer") from None


def is_writer() -> bool:
    """True in the process that writes outputs (process 0; the only process of a plain run)."""
    return jax.process_index() == 0


def to_host(tree: Any) -> Any:
    """Every leaf as a numpy array holding all of its values, gathered from every process."""
    if jax.process_count() == 1:
        return jax.tree.map(np.asarray, tree)
    from jax.experimental import multihost_utils

    def gather(x):
        if not isinstance(x, jax.Array) or x.is_fully_addressable:
            return np.asarray(x)
        if x.is_fully_replicated:  # every process holds all of it
            return np.asarray(x.addressable_data(0))
        return np.asarray(multihost_utils.process_allgather(x, tiled=True))

    return jax.tree.map(gather, tree)
