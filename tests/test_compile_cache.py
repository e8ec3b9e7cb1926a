"""The persistent compilation cache catches every program: a second run compiles nothing new.

Counted from JAX's monitoring events (`diffsense.report.CompileClock.compiled`: backend compile
requests less persistent-cache hits), recorded in result.json as wall_s.programs_compiled.
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
    compiled = []
    for run in ("cold", "warm"):
        out = tmp_path / run
        subprocess.run([sys.executable, "-m", "diffsense.optimise", "--scenarios", "sc01", "--variants", "1",
                        "--steps", "30,105,180", "--model", str(weights), "--out", str(out), "--quiet"],
                       cwd=ROOT, env=env, check=True, capture_output=True, timeout=900)
        compiled.append(json.loads((out / "result.json").read_text())["wall_s"]["programs_compiled"])
    assert compiled[0] > 10 and compiled[1] == 0, compiled
    assert any((tmp_path / "cache").iterdir())  # JAX_COMPILATION_CACHE_DIR is honoured
    assert list((tmp_path / "cache" / "executables").glob("*.exe"))  # the objective's programs too
