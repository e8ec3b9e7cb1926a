"""`CompileClock`, result.json's wall_s.compile, programs_compiled and programs_lowered: the seconds
of every trace, lowering, backend compile and program load JAX reports while it runs, the backend
compiles less persistent-cache hits, and the rest of the wall time; each event fed in by hand,
then a real compilation."""

from __future__ import annotations

import time

import jax
import numpy as np
from jax import monitoring

from diffsense.runtime import CompileClock

TRACE = "/jax/core/compile/jaxpr_trace_duration"
LOWER = "/jax/core/compile/jaxpr_to_mlir_module_duration"
BACKEND = "/jax/core/compile/backend_compile_duration"
LOAD = "/diffsense/executables/load_duration"
CACHE_HIT = "/jax/compilation_cache/cache_hits"


def test_each_compile_event_adds_its_seconds_and_the_rest_are_ignored():
    with CompileClock() as clock:
        for event, seconds in ((TRACE, 0.5), (LOWER, 0.25), (BACKEND, 1.0), (LOAD, 0.125), ("/jax/other", 8.0)):
            monitoring.record_event_duration_secs(event, seconds)
    assert clock.compile_s == 1.875
    assert (clock.backend_compiles, clock.lowered, clock.cache_hits) == (1, 1, 0)


def test_compiled_counts_backend_compiles_less_cache_hits():
    with CompileClock() as clock:
        for _ in range(3):
            monitoring.record_event_duration_secs(BACKEND, 0.0)
        monitoring.record_event(CACHE_HIT)
        monitoring.record_event(CACHE_HIT)
        monitoring.record_event("/jax/other_event")
    assert (clock.backend_compiles, clock.cache_hits, clock.compiled) == (3, 2, 1)


def test_nested_clocks_both_count_and_a_closed_clock_stops():
    with CompileClock() as outer:
        with CompileClock() as inner:
            monitoring.record_event_duration_secs(LOWER, 1.0)
            monitoring.record_event(CACHE_HIT)
        monitoring.record_event_duration_secs(LOWER, 2.0)
    monitoring.record_event_duration_secs(LOWER, 4.0)
    monitoring.record_event(CACHE_HIT)
    assert (outer.compile_s, outer.lowered, outer.cache_hits) == (3.0, 2, 1)
    assert (inner.compile_s, inner.lowered, inner.cache_hits) == (1.0, 1, 1)


def test_total_and_run_time():
    with CompileClock() as clock:
        time.sleep(0.05)
        monitoring.record_event_duration_secs(TRACE, 0.02)
    assert 0.05 <= clock.total_s < 5.0
    assert clock.run_s == clock.total_s - 0.02
    fresh = CompileClock()
    assert (fresh.compile_s, fresh.total_s, fresh.run_s, fresh.compiled, fresh.lowered) == (0.0, 0.0, 0.0, 0, 0)
    with CompileClock() as clock:
        monitoring.record_event_duration_secs(BACKEND, 100.0)  # a duration longer than the clock ran
    assert clock.run_s == 0.0  # never negative


def test_real_compilations_are_counted_once_per_program():
    jitted = jax.jit(lambda x: x * 3.0 + 1.25)
    with CompileClock() as clock:
        jitted(np.ones(3))  # traced, lowered and compiled (host arrays need no program of their own)
        jitted(np.zeros(3))  # the same shape: nothing new
        jitted(np.ones(4))  # a new shape: a second program
    assert clock.lowered == 2 and clock.compiled == 2 and clock.compile_s > 0.0
    with CompileClock() as clock:
        jitted(np.ones(4))
    assert (clock.lowered, clock.compiled) == (0, 0)
