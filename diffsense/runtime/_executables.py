"""Compiled programs kept on disk, so that a warm run neither traces nor lowers them.

JAX's persistent compilation cache saves the backend compilation, but it finds an entry by the
lowered program, so every run still traces and lowers each program to look it up: about a
second for the objective's value-and-gradient and hard programs together. `call(fn, *args)`
keeps the compiled executable itself, in a folder the command line sets (`keep_in`), under a
key computed without tracing: the function's name, the arguments' structure, shapes and static
values, a digest of this package's source files, the versions of the libraries that trace it,
JAX's settings and the machine's processor. A warm run loads the executable and calls it.

The folder is trusted as JAX's own cache folder is: an executable is loaded from a pickle there
(`jax.experimental.serialize_executable`), so it must be the user's own. Storing and loading use
two of JAX's private names (`jax._src.compiler.compile_or_get_cached`, the unpickler of
`serialize_executable`); the key holds JAX's version. Anything unusual (no folder set, several
devices or processes, a traced argument, a static value without an exact text, a node type from
outside the libraries named in `_TRUSTED_MODULES`, a file that does not load, a failure to
store) falls back to `equinox.filter_jit`, as the library does without the command line.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import importlib.metadata
import os
import pickle
import platform
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
from jax import monitoring

_folder: Path | None = None
_memory: dict[tuple, Callable[..., Any]] = {}
_jitted: dict[Callable[..., Any], Callable[..., Any]] = {}
_source_digest: str | None = None
_TRUSTED_MODULES = ("diffsense.", "flax.", "equinox.", "jax.", "jaxlib.", "builtins", "collections")
_LIBRARIES = ("jax", "jaxlib", "flax", "equinox", "numpy", "optimistix", "lineax")


def keep_in(folder: Path | None) -> None:
    """Keep compiled executables in `folder` (None: keep none; `call` is `equinox.filter_jit`)."""
    global _folder
    _folder = None if folder is None else Path(folder)
    _memory.clear()


def call(fn: Callable[..., Any], *args: Any) -> Any:
    """`fn(*args)` compiled as `equinox.filter_jit` compiles it: arrays traced, every other leaf
    static (baked into the program).

    The executable comes from the folder `keep_in` set when it holds one for the same key, else
    it is compiled and stored there; one compiled per key is kept in memory too.
    """
    dynamic, static = eqx.partition(args, eqx.is_array)
    leaves, treedef = jax.tree.flatten(dynamic)
    statics = _stable_repr(jax.tree.leaves(static))
    if statics is None or not _cacheable(leaves, treedef, jax.tree.structure(static)):
        return _filter_jit(fn)(*args)
    avals = tuple((leaf.shape, str(leaf.dtype), bool(getattr(leaf, "weak_type", False))) for leaf in leaves)
    memory_key = (fn, treedef, avals, jax.tree.structure(static), statics)
    if memory_key not in _memory:
        key = _disk_key(fn, treedef, avals, statics)
        path = _folder / f"{key}.exe"
        in_tree = jax.tree.structure(((dynamic,), {}))

        def program(d):
            return fn(*eqx.combine(d, static))

        # Named after fn (its module name in XLA's dumps and profiles) and its key.
        program.__name__ = program.__qualname__ = f"{fn.__name__}_{key[:16]}"
        try:
            _memory[memory_key] = _load(path, in_tree) or _compile_and_store(program, dynamic, path)
        except Exception:  # JAX's private names changed, say: compile as the library does
            return _filter_jit(fn)(*args)
    return _memory[memory_key](dynamic)


def _filter_jit(fn: Callable[..., Any]) -> Callable[..., Any]:
    if fn not in _jitted:
        _jitted[fn] = eqx.filter_jit(fn)
    return _jitted[fn]


def _stable_repr(statics: list[Any]) -> str | None:
    """The static leaves written out exactly (numbers, strings, frozen dataclasses of them), or
    None when one has no exact text (a function, an array held as a static field, ...)."""
    def text(value: Any) -> str | None:
        if value is None or isinstance(value, (bool, int, float, str)):
            return repr(value)
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            fields = [text(getattr(value, f.name)) for f in dataclasses.fields(value)]
            return None if None in fields else f"{type(value).__module__}.{type(value).__qualname__}({fields})"
        return None

    out = [text(v) for v in statics]
    return None if None in out else repr(out)


def _cacheable(leaves: list[Any], *treedefs: Any) -> bool:
    if _folder is None or jax.process_count() != 1 or jax.device_count() != 1:
        return False
    if any(isinstance(leaf, jax.core.Tracer) for leaf in leaves):  # inside a trace: jit inline
        return False
    return all(t.startswith(_TRUSTED_MODULES) for tree in treedefs for t in _node_modules(tree))


def _node_modules(treedef: Any) -> set[str]:
    """The modules of every node type in `treedef` (its own code is then covered by the key)."""
    out: set[str] = set()
    stack = [treedef]
    while stack:
        node = stack.pop()
        data = node.node_data()
        if data is not None:
            out.add(f"{data[0].__module__}.")
        stack.extend(node.children())
    return out


def _disk_key(fn: Callable[..., Any], treedef: Any, avals: tuple, statics: str) -> str:
    device = jax.devices()[0]
    parts = [
        f"{fn.__module__}.{fn.__qualname__}", repr(treedef), repr(avals), statics, _sources(),
        *(f"{name}={_version(name)}" for name in _LIBRARIES),
        f"x64={jax.config.jax_enable_x64}", f"matmul={jax.config.jax_default_matmul_precision}",
        f"XLA_FLAGS={os.environ.get('XLA_FLAGS', '')}",
        f"{device.platform}/{device.device_kind}/{device.client.platform_version}",
        platform.machine(), _cpu_flags(),
    ]
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()


def _sources() -> str:
    """A digest of every Python file of this package: a code change invalidates every entry."""
    global _source_digest
    if _source_digest is None:
        digest = hashlib.sha256()
        root = Path(__file__).parents[1]  # the diffsense package, not this folder
        for path in sorted(root.rglob("*.py")):
            digest.update(str(path.relative_to(root)).encode())
            digest.update(path.read_bytes())
        _source_digest = digest.hexdigest()
    return _source_digest


def _version(name: str) -> str:
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return "-"


def _cpu_flags() -> str:
    """The processor's feature flags: an executable compiled for one CPU may not run on another."""
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith(("flags", "Features")):
                return line
    return platform.processor()


LOAD_EVENT = "/diffsense/executables/load_duration"


def _load(path: Path, in_tree: Any) -> Callable[..., Any] | None:
    start = time.perf_counter()
    try:
        payload, out_tree, options = pickle.loads(path.read_bytes())
        program = _deserialize(payload, in_tree, out_tree, options)
    except Exception:  # a missing, partial or stale file: compile instead
        return None
    # Reported as JAX reports its compilations, so `CompileClock` counts loading as compiling.
    monitoring.record_event_duration_secs(LOAD_EVENT, time.perf_counter() - start)
    return program


def _deserialize(payload: bytes, in_tree: Any, out_tree: Any, options: bytes) -> Callable[..., Any]:
    """`serialize_executable.deserialize_and_load`, giving XLA the program's compile options as
    JAX's persistent cache does when it loads an executable."""
    import io

    from jax._src.lib import xla_client
    from jax.experimental import serialize_executable

    compile_options = xla_client.CompileOptions.ParseFromString(options)

    class Unpickler(serialize_executable._JaxPjrtUnpickler):
        def persistent_load(self, pid):
            if pid[0] == "exec":
                return self.backend.deserialize_executable(pid[1], self.execution_devices, compile_options)
            return super().persistent_load(pid)

    backend = jax.devices()[0].client
    unloaded, args_info_flat, no_kwargs = Unpickler(io.BytesIO(payload), backend).load()
    return jax.stages.Compiled(unloaded.load(), [], in_tree.unflatten(args_info_flat), out_tree, no_kwargs=no_kwargs)


def _compile_and_store(fn: Callable[..., Any], dynamic: Any, path: Path) -> Callable[..., Any]:
    from jax._src import compiler
    from jax.experimental import serialize_executable

    # Compiled afresh by XLA, never read from JAX's persistent cache: an executable JAX loaded
    # from there lacks the code of kernels XLA shares between programs, and its serialisation
    # fails when loaded ("Function ... not found"; tests/test_compiled_programs.py). JAX's flag to
    # disable the cache is read once per process, so the compile step itself is replaced here.
    options = []  # the compile options JAX gives XLA, kept for loading (see _deserialize)
    compile_or_get_cached = compiler.compile_or_get_cached

    def afresh(backend, computation, devices, compile_options, host_callbacks, executable_devices, *_):
        options.append(compile_options)
        return compiler.backend_compile_and_load(backend, computation, executable_devices, compile_options,
                                                 host_callbacks)

    compiler.compile_or_get_cached = afresh
    try:
        program = jax.jit(fn).lower(dynamic).compile()
    finally:
        compiler.compile_or_get_cached = compile_or_get_cached
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        (compile_options,) = options
        payload, _, out_tree = serialize_executable.serialize(program)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_bytes(pickle.dumps((payload, out_tree, compile_options.SerializeAsString())))
        os.replace(tmp, path)
    except Exception:  # a full disk, a read-only folder, an unpicklable output: only costs speed
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)
    return program
