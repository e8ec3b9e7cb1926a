"""The compiled-program store (`call`, `keep_in`): a warm run loads what a cold run stored, without
tracing, and gets the same bits as a compile; one program per static value, shape, weak type and
setting; a code change, a damaged file or an unusual argument (traced, a foreign node type,
several devices, a static value without an exact text) never loads a wrong program; a folder
that cannot be written costs only speed."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax import monitoring

from diffsense.runtime import CompileClock, call, keep_in

ROOT = Path(__file__).resolve().parents[1]


def _bowl(x, scale):
    """A small program with a reduction and a static number: scale * sum((x - 0.3)^2)."""
    return scale * jnp.sum((x - 0.3) ** 2), jnp.cumsum(x)


def _by_hand(x, scale):
    return scale * np.sum((np.asarray(x, np.float64) - 0.3) ** 2)


_traces: list[str] = []
monitoring.register_event_duration_secs_listener(
    lambda event, _d, **kw: _traces.append(kw.get("fun_name", "")) if event.endswith("jaxpr_trace_duration") else None)


@dataclasses.dataclass(frozen=True)
class _Cfg:
    n: int
    name: str


@jax.tree_util.register_pytree_node_class
class _Holder:
    """A node type from outside the libraries whose code the key covers."""

    def __init__(self, x):
        self.x = x

    def tree_flatten(self):
        return (self.x,), None

    @classmethod
    def tree_unflatten(cls, _aux, children):
        return cls(*children)


@pytest.fixture
def folder(tmp_path):
    keep_in(tmp_path / "a" / "executables")  # made with its parents
    yield tmp_path / "a" / "executables"
    keep_in(None)


def _files(folder: Path) -> list[Path]:
    return sorted(folder.glob("*.exe")) if folder.exists() else []


def test_a_warm_call_loads_what_a_cold_call_stored_with_the_same_bits(folder):
    x = jnp.linspace(-1.0, 2.0, 7)
    first = call(_bowl, x, 2.5)
    assert len(_files(folder)) == 1
    keep_in(folder)  # forgets the programs held in memory, as a new process would
    _traces.clear()
    with CompileClock() as clock:
        again = call(_bowl, x, 2.5)
    assert not [name for name in _traces if "_bowl" in name]  # loaded, not traced
    assert clock.lowered == 0 and clock.compiled == 0 and clock.compile_s > 0.0  # loading counts as compiling
    for a, b, c in zip(first, again, jax.jit(_bowl, static_argnums=1)(x, 2.5)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
        np.testing.assert_array_equal(np.asarray(a), np.asarray(c))
    np.testing.assert_allclose(float(again[0]), _by_hand(x, 2.5), rtol=1e-12)
    np.testing.assert_allclose(np.asarray(again[1]), np.cumsum(np.asarray(x)), rtol=0, atol=1e-15)


def test_each_static_value_shape_and_weak_type_has_a_program_of_its_own(folder):
    x = jnp.arange(4.0)
    two, three = call(_bowl, x, 2.0)[0], call(_bowl, x, 3.0)[0]
    longer = call(_bowl, jnp.arange(5.0), 2.0)[0]
    np.testing.assert_allclose([float(two), float(three), float(longer)],
                               [_by_hand(np.arange(4.0), 2.0), _by_hand(np.arange(4.0), 3.0),
                                _by_hand(np.arange(5.0), 2.0)], rtol=1e-12)
    assert len(_files(folder)) == 3
    call(_bowl, np.arange(4.0), 2.0)  # numpy has no weak type: keyed as a strong jax array
    assert len(_files(folder)) == 3
    weak, strong = jnp.asarray(2.0), jnp.asarray(2.0, dtype=jnp.float64)
    assert weak.weak_type and not strong.weak_type
    call(lambda v: v * 3, weak), call(lambda v: v * 3, strong)
    assert len(_files(folder)) == 5


def test_a_dataclass_of_numbers_is_a_static_value_of_its_own(folder):
    def scaled(x, cfg):
        return cfg.n * jnp.sum(x)

    x = jnp.arange(3.0)
    assert [float(call(scaled, x, _Cfg(n, "a"))) for n in (2, 3, 2)] == [6.0, 9.0, 6.0]
    assert len(_files(folder)) == 2


def test_a_setting_that_changes_the_program_is_a_key_of_its_own(folder, monkeypatch):
    x = jnp.arange(3.0)
    call(_bowl, x, 2.0)
    with jax.default_matmul_precision("highest"):
        keep_in(folder)
        call(_bowl, x, 2.0)
    assert len(_files(folder)) == 2
    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_enable_fast_math=false")
    keep_in(folder)
    np.testing.assert_allclose(float(call(_bowl, x, 2.0)[0]), _by_hand(np.arange(3.0), 2.0), rtol=1e-12)
    assert len(_files(folder)) == 3


def test_a_damaged_file_is_compiled_again_and_replaced(folder):
    x = jnp.arange(3.0)
    call(_bowl, x, 1.0)
    (path,) = _files(folder)
    path.write_bytes(b"not a program")
    keep_in(folder)
    np.testing.assert_allclose(float(call(_bowl, x, 1.0)[0]), _by_hand(np.arange(3.0), 1.0), rtol=1e-12)
    assert _files(folder) == [path] and [p.name for p in folder.iterdir()] == [path.name]  # no temporary
    keep_in(folder)
    _traces.clear()
    np.testing.assert_allclose(float(call(_bowl, x, 1.0)[0]), _by_hand(np.arange(3.0), 1.0), rtol=1e-12)
    assert not [name for name in _traces if "_bowl" in name]  # the file rewritten loads


def test_what_is_never_stored(folder, monkeypatch):
    # Under jax.grad the arguments are tracers: the program is jitted inline.
    grad = jax.grad(lambda x: call(_bowl, x, 2.0)[0])(jnp.arange(3.0))
    np.testing.assert_allclose(np.asarray(grad), 2.0 * 2.0 * (np.arange(3.0) - 0.3), rtol=1e-12)
    # a node type whose code the key does not cover; a static value with no exact text
    assert float(call(lambda h: 2.0 * jnp.sum(h.x), _Holder(jnp.arange(3.0)))) == 6.0
    assert float(call(lambda x, f: f(x), jnp.arange(3.0), jnp.sum)) == 3.0
    assert float(call(lambda x, b: len(b) * jnp.sum(x), jnp.arange(3.0), b"xy")) == 6.0
    # several devices or processes
    for name in ("device_count", "process_count"):
        with monkeypatch.context() as m:
            m.setattr(jax, name, lambda: 2)
            assert float(call(_bowl, jnp.arange(3.0), 7.0)[0]) == pytest.approx(_by_hand(np.arange(3.0), 7.0))
    assert _files(folder) == []


def test_without_a_folder_nothing_is_written(tmp_path, monkeypatch):
    keep_in(None)
    monkeypatch.chdir(tmp_path)
    assert float(call(_bowl, jnp.arange(3.0), 1.0)[0]) == pytest.approx(_by_hand(np.arange(3.0), 1.0))
    assert not list(tmp_path.iterdir())


def test_a_folder_that_cannot_be_written_costs_only_speed(tmp_path):
    (tmp_path / "a file").write_text("")
    keep_in(tmp_path / "a file" / "executables")
    try:
        value = call(_bowl, jnp.arange(3.0), 2.0)[0]
    finally:
        keep_in(None)
    np.testing.assert_allclose(float(value), _by_hand(np.arange(3.0), 2.0), rtol=1e-12)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a file"]


def test_a_failed_write_publishes_nothing_and_keeps_the_program(folder, monkeypatch):
    def refuse(src, dst):
        raise OSError("disk full")

    with monkeypatch.context() as m:
        m.setattr(os, "replace", refuse)
        value = call(_bowl, jnp.arange(3.0), 2.0)[0]
    np.testing.assert_allclose(float(value), _by_hand(np.arange(3.0), 2.0), rtol=1e-12)
    assert not list(folder.iterdir())  # neither the program nor its temporary
    _traces.clear()
    call(_bowl, jnp.arange(3.0), 2.0)
    assert not _traces  # the program compiled for the folder is kept for this process


def test_a_program_with_a_host_callback_keeps_it(folder):
    """XLA needs the host callbacks at compile time: without them such a program crashes."""
    def with_callback(x):
        return 2.0 * jax.pure_callback(np.sin, jax.ShapeDtypeStruct(x.shape, x.dtype), x)

    np.testing.assert_allclose(np.asarray(call(with_callback, jnp.arange(3.0))), 2.0 * np.sin(np.arange(3.0)),
                               rtol=1e-12)


_SCRIPT = textwrap.dedent("""
    import json, sys
    from pathlib import Path
    import jax, jax.numpy as jnp
    from jax import monitoring
    jax.config.update("jax_compilation_cache_dir", sys.argv[1])
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    from diffsense.runtime import call, keep_in
    traced = []
    monitoring.register_event_duration_secs_listener(
        lambda event, _d, **kw: traced.append(kw.get("fun_name", "")) if event.endswith("trace_duration") else None)
    def first(x): return jnp.sum(jnp.where(jnp.arange(7) < x, x, 0.0))
    def second(x): return jnp.sum(jnp.where(jnp.arange(9) > x, 2 * x, 1.0))
    keep_in(Path(sys.argv[2]))
    values = [float(call(first, jnp.float32(3.0))), float(jax.jit(second)(jnp.float32(3.0)))]
    print(json.dumps({"values": values, "traced": any(name.startswith("first") for name in traced)}))
""")


def test_a_new_process_loads_what_an_earlier_one_stored_until_the_code_changes(tmp_path):
    """Stored, its file deleted while JAX's persistent cache keeps what it saw, stored again, then
    loaded in a new process beside a program from JAX's cache (an executable JAX had read from its
    cache once stored a file whose programs failed when run); then one source file of the package
    changes: the next run compiles afresh."""
    package = tmp_path / "src"
    shutil.copytree(ROOT / "diffsense", package / "diffsense", ignore=shutil.ignore_patterns("__pycache__"))
    script = tmp_path / "run.py"
    script.write_text(_SCRIPT)
    jax_cache, folder = tmp_path / "jax", tmp_path / "executables"
    env = dict(os.environ, PYTHONPATH=str(package))
    runs = []
    for step in ("store", "delete and store again", "load", "edit and store"):
        if step.startswith("delete"):
            for path in _files(folder):
                path.unlink()
        if step.startswith("edit"):
            with open(package / "diffsense" / "runtime" / "_random.py", "a") as f:
                f.write("# a change\n")
        proc = subprocess.run([sys.executable, str(script), str(jax_cache), str(folder)], env=env, cwd=tmp_path,
                              capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, (step, proc.stderr[-2000:])
        runs.append(json.loads(proc.stdout.strip().splitlines()[-1]))
    # first: 3 * 3 (x = 3 where arange(7) < 3); second: 2 * 3 * 5 + 4 * 1 (arange(9) > 3 at 5 places)
    assert [r["values"] for r in runs] == [[9.0, 34.0]] * 4
    assert [r["traced"] for r in runs] == [True, True, False, True]
    assert len(_files(folder)) == 2


@pytest.mark.slow
def test_a_second_run_compiles_nothing(tmp_path):
    """result.json's wall_s.programs_compiled (backend compiles less cache hits) and _lowered."""
    from flax import nnx

    from diffsense.predictors import CSLSTM, save_weights

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
