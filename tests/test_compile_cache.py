"""The persistent compilation cache catches every program: a second run compiles nothing new.

Counted from JAX's monitoring events (`diffsense.report.CompileClock.compiled`: backend compile
requests less persistent-cache hits), recorded in result.json as wall_s.programs_compiled; and
the programs traced and lowered at all, wall_s.programs_lowered.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from flax import nnx

from diffsense.predictors import CSLSTM, save_weights

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_a_second_run_compiles_nothing(tmp_path):
    weights = tmp_path / "random.msgpack"
    save_weights(weights, CSLSTM(rngs=nnx.Rngs(0)))
    env = dict(os.environ, JAX_COMPILATION_CACHE_DIR=str(tmp_path / "cache"))
    env.pop("DIFFSENSE_NO_CACHE", None)
    compiled, lowered = [], []
    for run in ("cold", "warm"):
        out = tmp_path / run
        subprocess.run([sys.executable, "-m", "diffsense.optimise", "--scenarios", "sc01", "--variants", "1",
                        "--steps", "30,105,180", "--model", str(weights), "--out", str(out), "--quiet"],
                       cwd=ROOT, env=env, check=True, capture_output=True, timeout=900)
        wall_s = json.loads((out / "result.json").read_text())["wall_s"]
        compiled.append(wall_s["programs_compiled"])
        lowered.append(wall_s["programs_lowered"])
    assert compiled[0] > 10 and compiled[1] == 0, compiled
    # Warm, only the solver's two small secant programs are traced and lowered (to be found in
    # JAX's cache); every other program is loaded whole from executables/, or is host arrays.
    assert lowered[0] >= compiled[0] and lowered[1] <= 2, lowered
    assert any((tmp_path / "cache").iterdir())  # JAX_COMPILATION_CACHE_DIR is honoured
    assert list((tmp_path / "cache" / "executables").glob("*.exe"))  # the objective's programs too


def test_the_clock_counts_programs_lowered_and_compiled():
    import jax
    import numpy as np

    from diffsense.runtime._timing import CompileClock

    def shifted(x):
        return x * 3.0 + 1.25

    jitted = jax.jit(shifted)
    with CompileClock() as clock:
        jitted(np.ones(3))  # traced, lowered and compiled: no persistent cache in the tests
        jitted(np.zeros(3))  # the same shape: nothing new
        jitted(np.ones(4))  # a new shape: a second program
    assert clock.lowered == 2 and clock.compiled == 2 and clock.compile_s > 0.0
    with CompileClock() as clock:
        jitted(np.ones(4))
    assert clock.lowered == 0 and clock.compiled == 0
