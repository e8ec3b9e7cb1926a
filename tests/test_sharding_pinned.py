"""`shard_leading_axis` (`diffsense/metrics/_sharding.py`) by hand: one device leaves the variants
as they are; on 4 simulated CPU devices 3 variants are padded with a copy of the last one at
weight 0 and each device holds one row; a tree of one array is padded the same way."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from diffsense.metrics._sharding import shard_leading_axis

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = """
import json, jax, numpy as np
from diffsense.metrics._sharding import shard_leading_axis
x = np.arange(6.0).reshape(3, 2)                  # 3 variants, 2 numbers each
w = np.array([0.5, 0.25, 0.25])
out = {}
for n in (3, 4):
    xs, ws = (x, w) if n == 3 else (np.arange(8.0).reshape(4, 2), np.full(4, 0.25))
    sx, sw = shard_leading_axis((xs, ws), pad_weight_index=1)
    out[n] = {"x": np.asarray(sx).tolist(), "w": np.asarray(sw).tolist(),
              "devices": len(sx.sharding.device_set),
              "shards": sorted(s.data.shape[0] for s in sx.addressable_shards)}
out["one leaf"] = np.asarray(shard_leading_axis((np.arange(3.0),))[0]).tolist()  # no weights
print(json.dumps(out))
"""


def test_one_device_leaves_the_tree_as_it_is():
    x, w = np.arange(6.0).reshape(3, 2), np.array([0.5, 0.25, 0.25])
    sx, sw = shard_leading_axis((x, w), pad_weight_index=1)
    assert sx is x and sw is w


def test_four_devices_pad_with_zero_weight_and_split_the_rows():
    # Called here too (one device: a no-op) so that mutmut, which runs for each mutant only the
    # tests it saw reach the mutated function in this process, runs this test for its mutants;
    # the subprocess inherits the mutant under test from the environment.
    x = np.arange(3.0)
    assert shard_leading_axis((x,))[0] is x
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    three, four = out["3"], out["4"]
    assert three["x"] == [[0, 1], [2, 3], [4, 5], [4, 5]]       # the last variant repeated
    assert three["w"] == [0.5, 0.25, 0.25, 0.0]                  # at weight 0
    assert four["x"] == [[0, 1], [2, 3], [4, 5], [6, 7]] and four["w"] == [0.25] * 4
    for case in (three, four):
        assert case["devices"] == 4 and case["shards"] == [1, 1, 1, 1]  # one row per device
    assert out["one leaf"] == [0.0, 1.0, 2.0, 2.0]  # a tree of one array is padded the same way
