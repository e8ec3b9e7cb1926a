"""Compiled programs kept on disk (`diffsense.runtime._executables`): loaded without tracing, the same
bits as a compile, one per static value and shape, and safe fallbacks."""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import textwrap
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax import monitoring

from diffsense.runtime import _executables
from diffsense.runtime._executables import call, keep_in

ROOT = Path(__file__).resolve().parents[1]


def _bowl(x, scale):
    """A small program with a reduction and a static number: scale * sum((x - 0.3)^2)."""
    return scale * jnp.sum((x - 0.3) ** 2), jnp.cumsum(x)


_traces: list[str] = []
monitoring.register_event_duration_secs_listener(
    lambda event, _d, **kw: _traces.append(kw.get("fun_name", "")) if event.endswith("jaxpr_trace_duration") else None)


@pytest.fixture
def folder(tmp_path):
    keep_in(tmp_path / "executables")
    yield tmp_path / "executables"
    keep_in(None)


def _files(folder: Path) -> list[Path]:
    return sorted(folder.glob("*.exe")) if folder.exists() else []


def test_a_stored_program_is_loaded_without_tracing_and_gives_the_same_bits(folder):
    x = jnp.linspace(-1.0, 2.0, 7)
    first = call(_bowl, x, 2.5)
    assert len(_files(folder)) == 1
    keep_in(folder)  # forgets the programs held in memory, as a new process would
    _traces.clear()
    again = call(_bowl, x, 2.5)
    assert not [name for name in _traces if "_bowl" in name]  # loaded, not traced
    reference = jax.jit(_bowl, static_argnums=1)(x, 2.5)
    for a, b, c in zip(first, again, reference):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
        np.testing.assert_array_equal(np.asarray(a), np.asarray(c))
    # 2.5 * sum((x - 0.3)^2) by hand in numpy
    xs = np.linspace(-1.0, 2.0, 7)
    np.testing.assert_allclose(float(again[0]), 2.5 * np.sum((xs - 0.3) ** 2), rtol=1e-12)


def test_each_static_value_and_shape_has_a_program_of_its_own(folder):
    x = jnp.arange(4.0)
    two, three = call(_bowl, x, 2.0)[0], call(_bowl, x, 3.0)[0]
    longer = call(_bowl, jnp.arange(5.0), 2.0)[0]
    assert len(_files(folder)) == 3
    base = np.sum((np.arange(4.0) - 0.3) ** 2)
    np.testing.assert_allclose([float(two), float(three)], [2.0 * base, 3.0 * base], rtol=1e-12)
    np.testing.assert_allclose(float(longer), 2.0 * np.sum((np.arange(5.0) - 0.3) ** 2), rtol=1e-12)


def test_a_damaged_file_is_compiled_again_and_replaced(folder):
    x = jnp.arange(3.0)
    call(_bowl, x, 1.0)
    (path,) = _files(folder)
    path.write_bytes(b"not a program")
    keep_in(folder)
    value = call(_bowl, x, 1.0)[0]
    np.testing.assert_allclose(float(value), np.sum((np.arange(3.0) - 0.3) ** 2), rtol=1e-12)
    payload, out_tree, options = pickle.loads(path.read_bytes())  # rewritten whole
    assert payload and options
    assert not list(folder.glob(".*.tmp"))


def test_traced_arguments_and_foreign_types_are_compiled_as_before(folder):
    # Under jax.grad the arguments are tracers: the program is jitted inline, not stored.
    grad = jax.grad(lambda x: call(_bowl, x, 2.0)[0])(jnp.arange(3.0))
    np.testing.assert_allclose(np.asarray(grad), 2.0 * 2.0 * (np.arange(3.0) - 0.3), rtol=1e-12)
    assert _files(folder) == []

    # A node type from outside the libraries whose code the key covers: never stored.
    value = call(lambda h: 2.0 * jnp.sum(h.x), _Holder(jnp.arange(3.0)))
    assert float(value) == 6.0
    assert _files(folder) == []


@jax.tree_util.register_pytree_node_class
class _Holder:
    def __init__(self, x):
        self.x = x

    def tree_flatten(self):
        return (self.x,), None

    @classmethod
    def tree_unflatten(cls, _aux, children):
        return cls(*children)


def test_without_a_folder_nothing_is_written(tmp_path):
    keep_in(None)
    value = call(_bowl, jnp.arange(3.0), 1.0)[0]
    np.testing.assert_allclose(float(value), np.sum((np.arange(3.0) - 0.3) ** 2), rtol=1e-12)
    assert not list(tmp_path.iterdir())


def test_the_key_covers_the_source_the_settings_and_the_arguments(folder):
    leaves, treedef = jax.tree.flatten((jnp.arange(3.0),))
    avals = (((3,), "float64", False),)
    key = _executables._disk_key(_bowl, treedef, avals, "[2.0]")
    assert key != _executables._disk_key(_bowl, treedef, avals, "[3.0]")
    assert key != _executables._disk_key(_bowl, treedef, (((4,), "float64", False),), "[2.0]")
    assert key != _executables._disk_key(test_without_a_folder_nothing_is_written, treedef, avals, "[2.0]")
    assert _executables._stable_repr([1, 2.5, "x", None]) is not None
    assert _executables._stable_repr([lambda: 0]) is None  # no exact text: never stored
    assert _executables._stable_repr([np.ones(2)]) is None


_SCRIPT = textwrap.dedent("""
    import sys
    from pathlib import Path
    import jax, jax.numpy as jnp
    jax.config.update("jax_compilation_cache_dir", sys.argv[1])
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    from diffsense.runtime._executables import call, keep_in
    def first(x): return jnp.sum(jnp.where(jnp.arange(7) < x, x, 0.0))
    def second(x): return jnp.sum(jnp.where(jnp.arange(9) > x, 2 * x, 1.0))
    keep_in(Path(sys.argv[2]))
    print(float(call(first, jnp.float32(3.0))), float(jax.jit(second)(jnp.float32(3.0))))
""")


def test_programs_stored_beside_jax_s_cache_load_in_a_new_process(tmp_path):
    """The sequence that broke: a program stored, its file deleted while JAX's persistent cache
    keeps what it saw, stored again, then loaded in a new process beside a program from JAX's
    cache. Storing an executable that JAX had read from its cache gave a file whose programs
    failed when run ("Function select_reduce_fusion not found")."""
    script = tmp_path / "run.py"
    script.write_text(_SCRIPT)
    jax_cache, folder = tmp_path / "jax", tmp_path / "executables"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    outputs = []
    for step in ("store", "delete and store again", "load"):
        if step.startswith("delete"):
            for path in _files(folder):
                path.unlink()
        proc = subprocess.run([sys.executable, str(script), str(jax_cache), str(folder)], env=env,
                              capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, (step, proc.stderr[-2000:])
        outputs.append(proc.stdout.split())
    # first: 3 * 3 (x = 3 where arange(7) < 3); second: 2 * 3 * 5 + 4 * 1 (arange(9) > 3 at 5 places)
    assert outputs == [["9.0", "34.0"]] * 3
    assert len(_files(folder)) == 1


def test_a_failure_to_compile_for_the_folder_falls_back_to_the_library_s_jit(folder, monkeypatch):
    def broken(*_):
        raise TypeError("a private name of JAX changed")

    monkeypatch.setattr(_executables, "_compile_and_store", broken)
    value = call(_bowl, jnp.arange(3.0), 2.0)[0]
    np.testing.assert_allclose(float(value), 2.0 * np.sum((np.arange(3.0) - 0.3) ** 2), rtol=1e-12)
    assert _files(folder) == []
