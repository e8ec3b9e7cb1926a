"""Sharding scene variants over 4 simulated CPU devices gives the same E and dE/dr as one device."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = """
import json, jax
jax.config.update("jax_enable_x64", True)
from diffsense.solve import Evaluator
from tests._toy_pipeline import toy_objective
obj = toy_objective(n=3)  # 3 variants on 4 devices: exercises the zero-weight padding
ev = Evaluator(obj)
value, grad = ev.value_and_grad(42.0)
print(json.dumps({"devices": jax.local_device_count(), "e2": float(value), "grad": float(grad[0]),
                  "hard": ev.e_hard(42.0), "sharded": len(obj.data.weight.sharding.device_set)}))
"""


def _run(device_count: int) -> dict:
    env = dict(os.environ)
    env["XLA_FLAGS"] = f"--xla_force_host_platform_device_count={device_count}"
    env["JAX_PLATFORMS"] = "cpu"
    out = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, env=env, capture_output=True,
                         text=True, check=True, timeout=600)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_four_devices_match_one():
    one, four = _run(1), _run(4)
    assert one["devices"] == 1 and four["devices"] == 4 and four["sharded"] == 4
    for key in ("e2", "grad", "hard"):
        np.testing.assert_allclose(four[key], one[key], rtol=1e-6, atol=1e-12)
