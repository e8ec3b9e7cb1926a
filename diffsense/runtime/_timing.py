"""Wall time split into JAX compilation and the rest, measured, not estimated.

JAX reports the duration of every trace, lowering and backend compilation through its
monitoring hooks, and `diffsense.runtime._executables` reports each compiled program it loads from disk
the same way; `CompileClock` sums them while it is active.
"""

from __future__ import annotations

import time

from jax import monitoring

_COMPILE_EVENTS = (
    "/jax/core/compile/jaxpr_trace_duration",
    "/jax/core/compile/jaxpr_to_mlir_module_duration",
    "/jax/core/compile/backend_compile_duration",
    "/diffsense/executables/load_duration",  # a compiled program loaded (diffsense.runtime._executables)
)

_active: list["CompileClock"] = []
_registered = False


_BACKEND_COMPILE = "/jax/core/compile/backend_compile_duration"
_LOWERING = "/jax/core/compile/jaxpr_to_mlir_module_duration"


def _listener(event: str, duration_s: float, **_: object) -> None:
    if event in _COMPILE_EVENTS:
        for clock in _active:
            clock.compile_s += duration_s
            # A program reached the backend: compiled, or loaded from the persistent cache.
            clock.backend_compiles += event == _BACKEND_COMPILE
            clock.lowered += event == _LOWERING


def _event_listener(event: str, **_: object) -> None:
    if event == "/jax/compilation_cache/cache_hits":
        for clock in _active:
            clock.cache_hits += 1


class CompileClock:
    """`with CompileClock() as c: ...` then `c.compile_s`, `c.run_s`, `c.total_s` [s] and
    `c.compiled`, the programs XLA compiled (not loaded from the persistent cache)."""

    def __init__(self) -> None:
        self.compile_s = 0.0
        self.backend_compiles = 0
        self.cache_hits = 0
        self.lowered = 0
        self.total_s = 0.0
        self._t0 = 0.0

    def __enter__(self) -> CompileClock:
        global _registered
        if not _registered:
            monitoring.register_event_duration_secs_listener(_listener)
            monitoring.register_event_listener(_event_listener)
            _registered = True
        _active.append(self)
        self._t0 = time.perf_counter()
        return self

    def __exit__(self, *exc: object) -> None:
        self.total_s = time.perf_counter() - self._t0
        _active.remove(self)

    @property
    def compiled(self) -> int:
        """Programs XLA compiled, not loaded from the persistent compilation cache."""
        return self.backend_compiles - self.cache_hits

    @property
    def run_s(self) -> float:
        return max(self.total_s - self.compile_s, 0.0)
