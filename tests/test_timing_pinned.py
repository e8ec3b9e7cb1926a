"""`CompileClock`: result.json's wall_s.compile, programs_compiled and programs_lowered, counted
from the events JAX reports, each event fed in by hand and its effect pinned."""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
from jax import monitoring

from diffsense.runtime import _timing
from diffsense.runtime._timing import CompileClock

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
    assert inner not in _timing._active and outer not in _timing._active


def test_the_listeners_are_registered_once():
    with CompileClock():
        pass
    with CompileClock() as clock:
        monitoring.record_event_duration_secs(TRACE, 1.0)
    assert clock.compile_s == 1.0 and _timing._registered


def test_total_and_run_time():
    with CompileClock() as clock:
        time.sleep(0.05)
        monitoring.record_event_duration_secs(TRACE, 0.02)
    assert 0.05 <= clock.total_s < 5.0
    assert clock.run_s == clock.total_s - 0.02
    fresh = CompileClock()
    assert (fresh.compile_s, fresh.total_s, fresh.run_s, fresh.compiled, fresh.lowered) == (0.0, 0.0, 0.0, 0, 0)


def test_run_time_is_never_negative():
    with CompileClock() as clock:
        monitoring.record_event_duration_secs(BACKEND, 100.0)  # a duration longer than the clock ran
    assert clock.run_s == 0.0


def test_a_real_compilation_is_counted():
    f = jax.jit(lambda x: jnp.sin(x) * 3.0 + 1.25)
    x = jnp.arange(7.0).block_until_ready()  # its own small program, compiled before the clock
    with CompileClock() as clock:
        f(x).block_until_ready()
    assert clock.lowered == 1 and clock.backend_compiles == 1 and clock.compile_s > 0.0
