"""Faults, hostile files and misleading answers, as a user meets them: in a process of `python -m
diffsense.optimise` (and `diffsense.scene`), each with its promised outcome: one `error:` line
naming the culprit and exit 2 before any simulation, in bounded memory; an interrupt leaving the
previous output set; result.json's flags agreeing with its answer."""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import _torch_zip
import numpy as np
import pytest
from flax import nnx

from diffsense.predictors import CSLSTM, save_weights

ROOT = Path(__file__).resolve().parents[1]
SMALL = ["--scenarios", "sc01", "--variants", "1", "--steps", "30,105,180"]


def _cli(args, timeout=300, **kwargs):
    return subprocess.run([sys.executable, "-m", "diffsense.optimise", *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout, **kwargs)


def _refused(proc, needle, out: Path | None = None, within_s: float | None = None, t0: float = 0.0):
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stderr
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr
    if out is not None:
        assert not out.exists() or list(out.iterdir()) == []
    if within_s is not None:
        assert time.perf_counter() - t0 < within_s


@pytest.fixture(scope="module")
def weights(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("w") / "random.msgpack"
    save_weights(path, CSLSTM(rngs=nnx.Rngs(0)))
    return path


@pytest.mark.parametrize("args, needle", [
    (["--seed", "9223372036854775808"], "seed"),
    (["--model", "/"], "/"),
    (["--estimator", "mc", "--mc-samples", "10000000"], "--max-memory-gb"),
])
def test_bad_arguments_are_refused_before_any_simulation(tmp_path, args, needle):
    out, t0 = tmp_path / "out", time.perf_counter()
    # Refused in seconds: before simulating anything (a simulation alone takes over 10 s here).
    _refused(_cli(args + ["--out", str(out)]), needle, out, within_s=60.0, t0=t0)


def _stride_zero(path: Path) -> None:
    """A tensor whose strides of 0 view 16 GB of one element."""
    _torch_zip.write(path, {"w": np.ones((4, 4), np.float32)}, geometry={"w": (0, (1 << 20, 1 << 12), (0, 0), 16)})


def _deflate_bomb(path: Path) -> None:
    """1 GiB of zeros, about 1 MB on disk."""
    _torch_zip.write(path, {"w": np.ones((4, 4), np.float32)})
    with zipfile.ZipFile(path, "a", compression=zipfile.ZIP_DEFLATED) as z, \
            z.open("archive/data/1", "w", force_zip64=True) as f:
        for _ in range(1024):
            f.write(bytes(1 << 20))


@pytest.mark.parametrize("write", [_stride_zero, _deflate_bomb])
def test_hostile_checkpoints_are_refused_in_bounded_memory(tmp_path, write):
    ckpt = tmp_path / "hostile.tar"
    write(ckpt)

    def cap():  # the child may not take more than 1.5 GiB: the checkpoint's claims need far more
        resource.setrlimit(resource.RLIMIT_AS, (3 << 29, 3 << 29))

    _refused(_cli(["--model", str(ckpt), "--out", str(tmp_path / "o")], preexec_fn=cap), str(ckpt), tmp_path / "o")


@pytest.mark.slow
@pytest.mark.parametrize("sig, code, line", [(signal.SIGINT, 130, "interrupted"), (signal.SIGTERM, 143, "terminated")])
def test_interrupt_during_the_solve_leaves_the_previous_set(tmp_path, weights, sig, code, line):
    out = tmp_path / "out"
    out.mkdir()
    (out / "result.json").write_text('{"previous": true}')
    (out / "manifest.json").write_text('{"files": ["result.json"]}')
    proc = subprocess.Popen([sys.executable, "-m", "diffsense.optimise", *SMALL, "--model", str(weights),
                             "--out", str(out)], cwd=ROOT, stderr=subprocess.PIPE, text=True)
    seen = []
    for text in proc.stderr:  # wait until the evaluations run (inside the solver's host callbacks)
        seen.append(text)
        if "evaluation 6/" in text:
            proc.send_signal(sig)
            break
    rest = proc.stderr.read()
    assert proc.wait(timeout=120) == code, "".join(seen) + rest
    assert rest.strip().splitlines()[-1] == line and "Traceback" not in rest
    assert json.loads((out / "result.json").read_text()) == {"previous": True}
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json", "result.json"]  # no temporaries


@pytest.mark.slow
def test_answers_say_when_they_press_on_a_bound_or_lie_on_a_flat(tmp_path):
    # The shipped weights over an interval as wide as the domain: the flags in result.json must
    # agree with the near-optimal set and r* (see diffsense/solve/_answer.py for the rules).
    out = tmp_path / "wide"
    proc = _cli(["--scenarios", "sc01", "--variants", "1", "--interval", "0.01", "360", "--out", str(out), "--quiet"],
                timeout=900)
    assert proc.returncode == 0, proc.stderr
    result = json.loads((out / "result.json").read_text())
    r, (lo, hi) = result["r_star"]["hfov_deg"], result["interval"]
    pressing = min(r - lo, hi - r) <= 0.02 * (hi - lo)
    assert ("pressing_on_bound" in result["flags"]) == pressing
    holding = [iv for iv in result["near_optimal"]["intervals"] if iv[0] <= r <= iv[1]]
    assert len(holding) == 1
    assert ("flat" in result["flags"]) == (holding[0][1] - holding[0][0] >= 0.1 * (hi - lo))


def test_the_python_api_runs_in_the_precision_asked_for():
    script = ("import diffsense as ds, jax\n"
              "E = ds.objective(ds.Problem(scenarios=['sc01'], variants=1, prediction_stride_frames=40,"
              " predictor=ds.predictors.init_predictor()))\n"
              "print(E.dtype, jax.config.jax_enable_x64)\n")
    proc = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=600,
                          env=dict(os.environ, JAX_ENABLE_X64="0"))
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["float64", "True"]


@pytest.mark.slow
def test_an_interrupted_training_set_leaves_no_partial_folder(tmp_path):
    out = tmp_path / "data"
    proc = subprocess.Popen([sys.executable, "-m", "diffsense.scene", "generate", "--out", str(out),
                             "--samples", "2000000", "--no-progress"], cwd=ROOT, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 600
    while time.time() < deadline and not any(p.name.endswith(".partial") for p in tmp_path.iterdir()):
        time.sleep(0.5)
    time.sleep(2.0)
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=120) == 130
    assert proc.stderr.read().strip().splitlines()[-1] == "interrupted"
    assert list(tmp_path.iterdir()) == []


def test_outputs_get_the_umask_mode(tmp_path):
    out = tmp_path / "sc01.png"
    proc = subprocess.run([sys.executable, "-c", "import os; os.umask(0o027); import runpy, sys; "
                           f"sys.argv = ['diffsense.scene', 'show', 'sc01', '--out', {str(out)!r}]; "
                           "runpy.run_module('diffsense.scene', run_name='__main__')"],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert out.stat().st_mode & 0o777 == 0o640


@pytest.mark.slow
def test_a_flat_range_objective_says_so(tmp_path):
    out = tmp_path / "range"
    proc = _cli(["--scenarios", "sc01", "--variants", "1", "--param", "range", "--interval", "0.1", "1000",
                 "--out", str(out), "--quiet"], timeout=900)
    assert proc.returncode == 0, proc.stderr
    result = json.loads((out / "result.json").read_text())
    r = result["r_star"]["range_m"]
    holding = [iv for iv in result["near_optimal"]["intervals"] if iv[0] <= r <= iv[1]]
    assert len(holding) == 1
    flat = holding[0][1] - holding[0][0] >= 0.1 * (1000 - 0.1)
    assert ("flat" in result["flags"]) == flat
