"""Scene variants sharded over 4 simulated CPU devices (`make_objective` shards by default):
3 variants are padded with a copy of the last at weight 0, the weather and the noise keys the
same way, each device holds one row, 4 variants are not padded, and E, dE/dr and the hard E are
those of one device."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import equinox as eqx
import jax
import numpy as np
import pytest

from diffsense.sensors import Weather
from tests._toy_pipeline import toy_objective

ROOT = Path(__file__).resolve().parents[1]
RAIN = (1.0, 2.0, 3.0)  # a rain rate per variant, so the padded row's is seen to be the last one's

SCRIPT = """
import json, jax, numpy as np
jax.config.update("jax_enable_x64", True)
import equinox as eqx
from diffsense.sensors import Weather
from tests._toy_pipeline import toy_objective
vg = eqx.filter_jit(lambda o, r: jax.value_and_grad(lambda x: o.e2({"range_m": x}))(r))
out = {"devices": jax.local_device_count()}
for n in (3, 4):
    E = toy_objective(n=n, instants=2, weather=Weather(rain_mm_h=np.arange(1.0, n + 1.0)))
    value, grad = vg(E, 42.0)
    keys = np.asarray(jax.random.key_data(E.data.noise_key))
    out[n] = {"weight": np.asarray(E.data.weight).tolist(), "rain": np.asarray(E.weather.rain_mm_h).tolist(),
              "x_m": np.asarray(E.data.scenes.x_m)[:, 5, 1].tolist(), "keys": keys.reshape(len(keys), -1).tolist(),
              "devices": len(E.data.weight.sharding.device_set),
              "shards": sorted(s.data.shape[0] for s in E.data.scenes.x_m.addressable_shards),
              "e2": float(value), "grad": float(grad), "hard": float(E({"range_m": 42.0}, mode="hard"))}
print(json.dumps(out))
"""


def test_four_devices_pad_with_zero_weight_split_the_rows_and_match_one():
    # Built here too (one device: nothing padded) so that mutmut, which runs for each mutant only
    # the tests it saw reach the mutated function in this process, runs this test; the
    # subprocess inherits the mutant under test from the environment.
    one = toy_objective(n=3, instants=2, weather=Weather(rain_mm_h=np.asarray(RAIN)))
    assert np.asarray(one.data.weight).tolist() == [1.0, 1.0, 1.0]
    value, grad = eqx.filter_jit(lambda o, r: jax.value_and_grad(lambda x: o.e2({"range_m": x}))(r))(one, 42.0)
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    three, four = out["3"], out["4"]
    assert out["devices"] == 4
    assert three["weight"] == [1.0, 1.0, 1.0, 0.0] and four["weight"] == [1.0] * 4
    assert three["rain"] == [*RAIN, 3.0] and four["rain"] == [1.0, 2.0, 3.0, 4.0]
    for key in ("x_m", "keys"):
        assert three[key][3] == three[key][2] and three[key][2] != three[key][1]  # the last variant repeated
    assert len(set(map(tuple, four["keys"]))) == 4
    for case in (three, four):
        assert case["devices"] == 4 and case["shards"] == [1, 1, 1, 1]  # one row per device
    np.testing.assert_allclose([three["e2"], three["grad"]], [float(value), float(grad)], rtol=1e-6, atol=1e-12)
    assert three["hard"] == pytest.approx(float(one({"range_m": 42.0}, mode="hard")), rel=1e-12)
