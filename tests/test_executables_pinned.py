"""`diffsense.runtime._executables` pinned: the key's recipe and what changes it, the exact text of static
values, which arguments are never stored, the file's name and how it is written, loading as an
event the compile clock counts, and the programs held in memory."""

from __future__ import annotations

import collections
import dataclasses
import hashlib
import importlib.metadata
import os
import platform
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax import monitoring
from jax._src import compiler

import diffsense
from diffsense.runtime import _executables as ex
from diffsense.runtime._executables import call, keep_in
from tests.test_executables import _bowl, _files, _Holder

_events: list[tuple[str, str]] = []
_load_s: list[float] = []
monitoring.register_event_duration_secs_listener(
    lambda event, duration, **kw: (_events.append((event, kw.get("fun_name", ""))), _load_s.append(duration)
                                   if event == ex.LOAD_EVENT else None)
    if event.endswith("jaxpr_trace_duration") or event == ex.LOAD_EVENT else None)


@pytest.fixture
def folder(tmp_path):
    keep_in(tmp_path / "executables")
    yield tmp_path / "executables"
    keep_in(None)


@dataclasses.dataclass(frozen=True)
class _Cfg:
    n: int
    name: str


@dataclasses.dataclass(frozen=True)
class _Outer:
    cfg: _Cfg
    fn: object


def test_static_values_are_written_out_exactly():
    assert ex._stable_repr([1, 2.5, "x", None, True]) == repr(["1", "2.5", "'x'", "None", "True"])
    here = __name__
    inner = f"{here}._Cfg({['3', repr('a')]!r})"  # a dataclass: its fields' texts in a list
    assert ex._stable_repr([_Cfg(3, "a")]) == repr([inner])
    assert ex._stable_repr([_Outer(_Cfg(3, "a"), 0.5)]) == repr([f"{here}._Outer({[inner, '0.5']!r})"])
    assert ex._stable_repr([]) == "[]"
    for no_text in (_Outer(_Cfg(1, "a"), len), _Cfg, len, np.ones(2), (1, 2), b"x"):
        assert ex._stable_repr([1.0, no_text]) is None, no_text


def test_the_node_types_modules():
    x = jnp.arange(3.0)
    tree = ({"k": x}, [x], (x,), collections.OrderedDict(a=x))
    assert ex._node_modules(jax.tree.structure(tree)) == {"builtins.", "collections."}
    assert ex._node_modules(jax.tree.structure(_Holder(x))) == {f"{_Holder.__module__}."}
    assert ex._node_modules(jax.tree.structure(x)) == set()


def test_what_is_never_stored(folder, monkeypatch):
    x = jnp.arange(3.0)
    leaves, treedef = jax.tree.flatten((x, {"a": x}))
    assert ex._cacheable(leaves, treedef)
    assert not ex._cacheable(leaves, treedef, jax.tree.structure(_Holder(x)))  # every tree is checked
    inside = []
    jax.grad(lambda v: inside.append(ex._cacheable([x, v], treedef)) or jnp.sum(v))(x)
    assert inside == [False]
    monkeypatch.setattr(jax, "device_count", lambda: 2)
    assert not ex._cacheable(leaves, treedef)
    monkeypatch.setattr(jax, "device_count", lambda: 1)
    monkeypatch.setattr(jax, "process_count", lambda: 2)
    assert not ex._cacheable(leaves, treedef)
    monkeypatch.setattr(jax, "process_count", lambda: 1)
    assert ex._cacheable(leaves, treedef)
    keep_in(None)
    assert not ex._cacheable(leaves, treedef)


def _key_parts(fn, treedef, avals, statics) -> list[str]:
    device = jax.devices()[0]
    return [f"{fn.__module__}.{fn.__qualname__}", repr(treedef), repr(avals), statics, ex._sources(),
            *(f"{n}={importlib.metadata.version(n)}" for n in ("jax", "jaxlib", "flax", "equinox", "numpy",
                                                                "optimistix", "lineax")),
            "x64=True", "matmul=None", f"XLA_FLAGS={os.environ.get('XLA_FLAGS', '')}",
            f"cpu/{device.device_kind}/{device.client.platform_version}", platform.machine(), ex._cpu_flags()]


def test_the_keys_recipe_and_what_changes_it(monkeypatch):
    treedef = jax.tree.structure((jnp.arange(3.0), None))
    avals = (((3,), "float64", False),)
    key = ex._disk_key(_bowl, treedef, avals, "['2.0']")
    expected = hashlib.sha256("\n".join(_key_parts(_bowl, treedef, avals, "['2.0']")).encode()).hexdigest()
    assert key == expected
    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_enable_fast_math=false")
    assert ex._disk_key(_bowl, treedef, avals, "['2.0']") != key
    monkeypatch.delenv("XLA_FLAGS", raising=False)
    with jax.default_matmul_precision("highest"):
        assert ex._disk_key(_bowl, treedef, avals, "['2.0']") != key
    monkeypatch.setattr(ex, "_version", lambda name: "0" if name == "lineax" else importlib.metadata.version(name))
    assert ex._disk_key(_bowl, treedef, avals, "['2.0']") != key
    for name, value in (("_source_digest", "another source"), ("_cpu_flags", lambda: "flags : fpu")):
        monkeypatch.undo()
        monkeypatch.setattr(ex, name, value)
        assert ex._disk_key(_bowl, treedef, avals, "['2.0']") != key, name
    monkeypatch.undo()
    monkeypatch.setattr(platform, "machine", lambda: "aarch64")
    assert ex._disk_key(_bowl, treedef, avals, "['2.0']") != key
    monkeypatch.undo()
    assert ex._disk_key(_bowl, treedef, (((3,), "float64", True),), "['2.0']") != key
    assert ex._disk_key(_bowl, treedef, avals, "['2.0']") == key


def test_the_source_digest_covers_every_file_of_the_package(monkeypatch):
    root = Path(diffsense.__file__).parent
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    monkeypatch.setattr(ex, "_source_digest", None)
    assert ex._sources() == digest.hexdigest()
    assert ex._source_digest == digest.hexdigest()  # read once per process
    assert any(p.parent != root for p in root.rglob("*.py"))  # subpackages are in it


def test_versions_and_the_processor(monkeypatch):
    assert ex._version("numpy") == np.__version__
    assert ex._version("no-such-distribution-here") == "-"
    flags = next(line for line in Path("/proc/cpuinfo").read_text().splitlines() if line.startswith("flags"))
    assert ex._cpu_flags() == flags
    monkeypatch.setattr(Path, "read_text", lambda self: "processor\t: 0\nFeatures\t: fp asimd\nflags\t: x\n")
    assert ex._cpu_flags() == "Features\t: fp asimd"

    def unreadable(self):
        raise OSError("no /proc here")

    monkeypatch.setattr(Path, "read_text", unreadable)
    assert ex._cpu_flags() == platform.processor()


def test_the_files_name_and_how_it_is_written(folder, monkeypatch):
    x = jnp.linspace(-1.0, 2.0, 7)
    moves = []
    real_replace = os.replace
    monkeypatch.setattr(ex.os, "replace", lambda src, dst: (moves.append((Path(src), Path(dst))), real_replace(src, dst)))
    _events.clear()
    call(_bowl, x, 2.5)
    key = ex._disk_key(_bowl, jax.tree.structure((x, None)), (((7,), "float64", False),), repr(["2.5"]))
    assert _files(folder) == [folder / f"{key}.exe"]
    assert moves == [(folder / f".{key}.exe.{os.getpid()}.tmp", folder / f"{key}.exe")]
    traced = {name for event, name in _events if event.endswith("jaxpr_trace_duration")}
    assert f"_bowl_{key[:16]}" in traced  # named after the function and its key
    assert not [e for e, _ in _events if e == ex.LOAD_EVENT]
    assert compiler.compile_or_get_cached.__name__ == "compile_or_get_cached"  # put back


def test_a_folder_that_cannot_be_written_costs_only_speed(tmp_path):
    (tmp_path / "a file").write_text("")
    keep_in(tmp_path / "a file" / "executables")
    try:
        value = call(_bowl, jnp.arange(3.0), 2.0)[0]
    finally:
        keep_in(None)
    np.testing.assert_allclose(float(value), 2.0 * np.sum((np.arange(3.0) - 0.3) ** 2), rtol=1e-12)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a file"]


def test_loading_is_an_event_and_memory_is_asked_first(folder, monkeypatch):
    x = jnp.arange(4.0)
    call(_bowl, x, 1.0)
    keep_in(str(folder))  # a new process's memory; a string names the folder too
    assert ex._folder == folder and ex._memory == {}
    _events.clear()
    _load_s.clear()
    start = time.perf_counter()
    first = call(_bowl, x, 1.0)[0]
    wall_s = time.perf_counter() - start
    assert [e for e, _ in _events if e == ex.LOAD_EVENT] == [ex.LOAD_EVENT]
    assert len(_load_s) == 1 and 0.0 <= _load_s[0] <= wall_s  # the load's own duration
    assert ex.LOAD_EVENT == "/diffsense/executables/load_duration"
    monkeypatch.setattr(ex, "_load", lambda *a: pytest.fail("loaded again"))
    assert float(call(_bowl, x, 1.0)[0]) == float(first)
    assert len(ex._memory) == 1
    monkeypatch.undo()
    assert ex._load(folder / "missing.exe", jax.tree.structure(((x,), {}))) is None


def test_weak_and_strong_arrays_get_programs_of_their_own(folder):
    weak, strong = jnp.asarray(2.0), jnp.asarray(2.0, dtype=jnp.float64)
    assert weak.weak_type and not strong.weak_type
    call(lambda v: v * 3, weak)
    call(lambda v: v * 3, strong)
    assert len(_files(folder)) == 2


def test_the_library_jit_is_made_once_per_function():
    def f(v):
        return v + 1

    assert ex._filter_jit(f) is ex._filter_jit(f)
    assert isinstance(ex._filter_jit(f), type(eqx.filter_jit(f)))
    assert float(ex._filter_jit(f)(jnp.asarray(1.0))) == 2.0


def test_a_folder_is_made_with_its_parents(tmp_path):
    keep_in(tmp_path / "a" / "b" / "executables")
    try:
        call(_bowl, jnp.arange(3.0), 2.0)
    finally:
        keep_in(None)
    assert len(_files(tmp_path / "a" / "b" / "executables")) == 1


@pytest.mark.parametrize("unlink_fails", [False, True])
def test_a_failed_write_leaves_nothing_and_keeps_the_program(folder, monkeypatch, unlink_fails):
    def refuse(src, dst):
        raise OSError("disk full")

    def cannot_unlink(self, missing_ok=False):
        raise PermissionError("read-only")

    monkeypatch.setattr(ex.os, "replace", refuse)
    if unlink_fails:
        monkeypatch.setattr(Path, "unlink", cannot_unlink)
    value = call(_bowl, jnp.arange(3.0), 2.0)[0]
    monkeypatch.undo()
    np.testing.assert_allclose(float(value), 2.0 * np.sum((np.arange(3.0) - 0.3) ** 2), rtol=1e-12)
    assert len(ex._memory) == 1  # compiled for the folder, kept for this process
    leftovers = sorted(p.name for p in folder.iterdir())
    assert not [n for n in leftovers if n.endswith(".exe")]  # nothing published
    assert len(leftovers) == (1 if unlink_fails else 0)  # the temporary only where it could not go
    _events.clear()
    call(_bowl, jnp.arange(3.0), 2.0)
    assert not _events  # neither traced nor loaded again


def test_a_program_with_a_host_callback_keeps_it(folder):
    """XLA needs the host callbacks at compile time: without them such a program crashes."""
    def with_callback(x):
        return 2.0 * jax.pure_callback(np.sin, jax.ShapeDtypeStruct(x.shape, x.dtype), x)

    value = call(with_callback, jnp.arange(3.0))
    np.testing.assert_allclose(np.asarray(value), 2.0 * np.sin(np.arange(3.0)), rtol=1e-12)


def test_a_numpy_argument_shares_the_program_of_a_strong_jax_array(folder):
    """numpy arrays have no weak type: they are keyed as strong, as JAX traces them."""
    value = call(_bowl, np.arange(3.0), 2.0)[0]
    np.testing.assert_allclose(float(value), 2.0 * np.sum((np.arange(3.0) - 0.3) ** 2), rtol=1e-12)
    call(_bowl, jnp.arange(3.0), 2.0)
    assert len(_files(folder)) == 1
