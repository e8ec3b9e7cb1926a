"""Test-wide settings: float64 available (gradient checks need it), paths to shared test data."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

# The suite compiles with JAX's `jax_disable_most_optimizations` (XLA's CPU backend at
# optimisation level 0, its expensive LLVM passes off): most of the suite's time is compiling
# programs that then run once or twice, and the flag cuts the suite's CPU time by about 30 %
# (docs/development.md). It is set in the environment, before JAX is imported, so the commands a
# test launches as subprocesses compile the same way. `JAX_DISABLE_MOST_OPTIMIZATIONS=0` runs
# the suite on the fully optimised compile that users get.
os.environ.setdefault("JAX_DISABLE_MOST_OPTIMIZATIONS", "1")

import jax
import pytest

from diffsense.runtime import keep_in

jax.config.update("jax_enable_x64", True)
# No test reads or writes the user's persistent compilation cache: a command run in-process
# (`main([...])`) would otherwise switch it on for every later test of the session, which then
# depends on whatever other runs left there. The tests of the cache give it a folder of their own.
os.environ.setdefault("DIFFSENSE_NO_CACHE", "1")
# The session keeps its own cache instead, in a fresh temporary folder (removed when the session
# ends, unless a signal kills it): the programs a test module compiles are dropped after it
# (below), and the next module that builds the same objective would compile them again. Only
# programs that take a second or more to compile are written (JAX's default), so small programs,
# such as the clock test's, are always compiled afresh.
_SESSION_CACHE = tempfile.TemporaryDirectory(prefix="diffsense-test-jax-cache-")
jax.config.update("jax_compilation_cache_dir", _SESSION_CACHE.name)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    """Drop JAX's compiled programs after each test module, so one process running the whole
    suite does not keep every executable it ever compiled. Without it the suite's process
    segfaulted inside XLA (compiling, or loading an executable) at 97 % of the suite, twice, in
    a test that passes alone; an executable count near the kernel's limit of 65530 memory
    mappings per process is the suspected cause, not a proven one."""
    yield
    jax.clear_caches()
    keep_in(None)  # a command run in-process may have set a folder for compiled programs


ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
NGSIM_WEIGHTS = SHARED / "weights" / "ngsim"


@pytest.fixture
def ngsim_checkpoint():
    """Path factory for a published NGSIM checkpoint; skips when ../shared is absent."""

    def get(name: str) -> Path:
        path = NGSIM_WEIGHTS / name
        if not path.is_file():
            pytest.skip(f"published checkpoint {path} not present (../shared/weights/ngsim)")
        return path

    return get
