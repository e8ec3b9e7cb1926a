"""benchmarks/bench_scaling.py: its rows, its table and its JSON are well-formed (correctness only)."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_scaling.py"


def _module():
    spec = importlib.util.spec_from_file_location("bench_scaling", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_configurations_list_each_row_once_in_order():
    bench = _module()
    args = bench._parser().parse_args(["--variants", "8,16", "--scenarios", "1,6", "--devices", "1,4"])
    rows = bench.configurations(args)
    # (8 variants, 6 scenarios) is both a variant row and a scenario row: it runs once per device count.
    assert rows == [(1, 8, 6), (1, 16, 6), (1, 8, 1), (4, 8, 6), (4, 16, 6), (4, 8, 1)]


def test_a_failed_configuration_is_a_row_of_its_own():
    bench = _module()
    good = {"devices": 1, "variants": 2, "scenarios": 1, "scenes": 2, "build_s": 1.0, "compile_value_s": 2.0,
            "compile_value_and_grad_s": 3.0, "value_s": 0.01, "value_and_grad_s": 0.02, "ratio": 2.0,
            "reverse_ratio": 2.75, "forward_ratio": 2.6, "value_and_grad_per_scene_ms": 10.0, "peak_rss_mb": 700.0}
    bad = {"devices": 4, "variants": 256, "scenarios": 6, "scenes": 1536, "error": "exit -9 (killed: out of memory?)"}
    lines = bench.table([good, bad]).splitlines()
    widths = {line.count("|") for line in lines}
    assert len(widths) == 1 and len(lines) == 4
    assert "| 1 | 2 | 1 | 2 | 1.0 | 2.0 / 3.0 | 0.010 | 0.020 | 2.00 | 2.75 | 2.60 | 10.0 | 700 |" in lines
    assert "failed: exit -9" in lines[3]
    old = {k: v for k, v in good.items() if k != "forward_ratio"}  # a row of a JSON from before the column
    assert "| 2.00 | 2.75 | - | 10.0 |" in bench.table([old])


def test_forward_tangents_give_the_reverse_gradient():
    import jax
    import jax.numpy as jnp

    bench = _module()
    fn = lambda r: r["a"] ** 2 * jnp.sin(r["b"]) + jnp.exp(0.3 * r["b"])
    r = {"a": jnp.asarray(1.7), "b": jnp.asarray(-0.4)}
    value, grad = jax.jit(lambda r: bench._forward_tangents(fn, r))(r)
    want_value, want = jax.value_and_grad(fn)(r)
    assert value == pytest.approx(float(want_value), rel=1e-14)
    assert grad["a"] == pytest.approx(2 * 1.7 * np.sin(-0.4), rel=1e-13)
    assert grad["b"] == pytest.approx(float(want["b"]), rel=1e-13)
    assert float(want["b"]) == pytest.approx(1.7**2 * np.cos(-0.4) + 0.3 * np.exp(-0.12), rel=1e-13)


@pytest.mark.parametrize("argv", [["--param", "hfov_deg,range_m", "--interval", "30", "180"],
                                  ["--param", "hfov_deg,range_m", "--interval", "30", "180", "50", "250"],
                                  ["--interval", "30", "180", "50"]])
def test_each_parameter_needs_its_interval_and_point(argv, monkeypatch, capsys):
    bench = _module()
    monkeypatch.setattr(sys, "argv", ["bench_scaling.py", *argv])
    with pytest.raises(SystemExit) as exit_:
        bench.main()
    assert exit_.value.code == 2
    assert "--interval numbers and" in capsys.readouterr().err


@pytest.mark.slow
def test_tiny_run_prints_a_table_and_writes_consistent_json(tmp_path):
    out = tmp_path / "scaling.json"
    done = subprocess.run([sys.executable, str(SCRIPT), "--variants", "2", "--base-scenarios", "1", "--scenarios", "",
                           "--devices", "1,2", "--repeats", "1", "--json", str(out)],
                          capture_output=True, text=True, timeout=900, check=True)
    lines = [line for line in done.stdout.splitlines() if line.startswith("|")]
    assert len(lines) == 4 and lines[0].startswith("| devices | variants |")
    assert "load average" in done.stdout
    rows = json.loads(out.read_text())["rows"]
    assert [(r["devices"], r["sharded_over"], r["variants"], r["scenarios"]) for r in rows] == [(1, 1, 2, 1), (2, 2, 2, 1)]
    for row in rows:
        assert "error" not in row and row["dtype"] == "float64"
        assert row["value_s"] > 0 and row["value_and_grad_s"] > 0 and row["peak_rss_mb"] > 0
        assert row["ratio"] == pytest.approx(row["value_and_grad_s"] / row["value_s"], rel=1e-12)
        assert row["reverse_ratio"] > 0 and row["forward_ratio"] == row["ratio"]  # one parameter: the same program
        assert row["value_and_grad_per_scene_ms"] == pytest.approx(1e3 * row["value_and_grad_s"] / 2, rel=1e-12)
