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
"""

from __future__ import annotations

import os
from typing import Any

import jax
import numpy as np

from diffsense.runtime._errors import InputError

_ENV = {"coordinator": "JAX_COORDINATOR_ADDRESS", "num_processes": "JAX_NUM_PROCESSES", "process_id": "JAX_PROCESS_ID"}


def initialize(coordinator: str | None = None, num_processes: int | None = None, process_id: int | None = None) -> None:
    """Join the run's processes (call before any JAX computation; a second call does nothing)."""
    if jax.distributed.is_initialized():
        return
    given = {"coordinator": coordinator, "num_processes": num_processes, "process_id": process_id}
    for name, var in _ENV.items():
        if given[name] is None and os.environ.get(var):
            given[name] = os.environ[var] if name == "coordinator" else _int(var, os.environ[var])
    if given["coordinator"] is not None:
        _check_address(given["coordinator"])
    if given["num_processes"] is not None and given["num_processes"] < 1:
        raise InputError(f"distributed: the process count must be >= 1, got {given['num_processes']}")
    if given["process_id"] is not None and given["num_processes"] is not None and not (
            0 <= given["process_id"] < given["num_processes"]):
        raise InputError(f"distributed: process id {given['process_id']} is not in 0..{given['num_processes'] - 1}")
    # CPU hosts need a collectives backend for cross-process reductions; GPU/TPU bring their own.
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    try:
        jax.distributed.initialize(coordinator_address=given["coordinator"], num_processes=given["num_processes"],
                                   process_id=given["process_id"])
    except (RuntimeError, ValueError) as e:
        raise InputError(f"distributed: cannot join the run: {e}") from None


def _check_address(address: str) -> None:
    """Refuse a coordinator address that is not HOST:PORT with a port in 1..65535."""
    host, sep, port = address.rpartition(":")
    if not sep or not host or not port.isdigit() or not 1 <= int(port) <= 65535:
        raise InputError(f"distributed: the coordinator address must be HOST:PORT with a port in 1..65535, "
                         f"got {address[:80]!r}")


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
