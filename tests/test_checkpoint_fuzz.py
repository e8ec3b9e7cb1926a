"""Hostile checkpoints: hundreds of deterministic corruptions of a valid file, each loaded by
`read_state_dict` in a child process allowed 1 GiB of address space beyond what the interpreter
and the library hold, end as one clean InputError line naming the file or as a valid load of
float32 arrays; never another exception, a crash, a memory error, or code from the file running."""

from __future__ import annotations

import io
import json
import os
import pickle
import struct
import subprocess
import sys
import zipfile
from pathlib import Path

import _torch_zip
import numpy as np
import pytest

CAP = 1 << 30  # RLIMIT_AS of each child beyond its address space once the reader is imported [bytes]
MiB = 1 << 20

# The reader as users import it; the cap is set once it is imported (the library's imports map
# hundreds of MiB that no file can make it allocate).
CHILD = r"""
import json, resource, sys
cap = int(sys.argv[1])
import numpy as np
from diffsense.predictors import read_state_dict
from diffsense.runtime import InputError

def status(key):
    return [int(line.split()[1]) for line in open("/proc/self/status") if line.startswith(key + ":")][0]

resource.setrlimit(resource.RLIMIT_AS, (status("VmSize") * 1024 + cap,) * 2)
base_kib = status("VmRSS")
for path in sys.stdin.read().split("\n"):
    if not path:
        continue
    try:
        sd = read_state_dict(path)
        good = isinstance(sd, dict) and all(
            isinstance(k, str) and isinstance(v, np.ndarray) and v.dtype == np.float32 for k, v in sd.items())
        out = ["ok" if good else "not float32 arrays", ""]
    except InputError as e:
        msg = str(e)
        out = ["input_error" if "\n" not in msg and path in msg else "error without the file", msg]
    except MemoryError:
        out = ["MemoryError", ""]
    except BaseException as e:  # noqa: BLE001 - what escapes is the finding
        out = ["escaped " + type(e).__name__, str(e)[:200]]
    print(json.dumps([path, *out]), flush=True)
# The peak resident memory of this process beyond what it held before the first file (VmHWM, of
# its own memory map: ru_maxrss also counts the forking parent's RSS at fork time).
print(json.dumps(["peak_kib", status("VmHWM") - base_kib, ""]), flush=True)
"""

STATE = {
    "lstm.weight": np.arange(24, dtype=np.float32).reshape(8, 3) / 7,
    "lstm.bias": np.linspace(-1, 1, 8, dtype=np.float32),
    "fc.weight": np.ones((2, 1, 4), np.float32),
}
W = "lstm.weight"  # the tensor whose geometry the explicit cases edit (8 x 3, storage "0")


def _zip(files: dict[str, bytes], compression: int = zipfile.ZIP_STORED) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression) as z:
        for name, data in files.items():
            z.writestr(name, data)
    return buf.getvalue()


def _members(pkl: bytes, storage0: bytes | None = None) -> dict[str, bytes]:
    files = {"archive/data.pkl": pkl}
    for i, arr in enumerate(STATE.values()):
        files[f"archive/data/{i}"] = arr.tobytes() if i or storage0 is None else storage0
    return files


def _flip(rng, data: bytes, lo: int = 0) -> bytes:
    b = bytearray(data)
    for _ in range(rng.integers(1, 4)):
        i = int(rng.integers(lo, len(b)))
        b[i] ^= 1 << int(rng.integers(0, 8))
    return bytes(b)


def _geometry_cases() -> list[tuple[str, tuple, str]]:
    """(name, (offset, size, stride, numel) of `W`, expected: "ok" or a needle of the refusal)."""
    big = 1 << 29
    return [
        ("transposed view", (0, (3, 8), (1, 3), 24), "ok"),
        ("size-1 dim, wild stride", (0, (8, 1, 3), (3, 1 << 50, 1), 24), "ok"),
        ("empty, huge dim", (0, (0, 1 << 30), (1, 1), 24), "over the limit"),
        ("empty tensor", (5, (0, 3), (3, 1), 24), "ok"),
        ("stride 0, 2 GB", (0, (big,), (0,), 24), "over the limit"),
        ("stride 0, in limits", (0, (8, 3), (0, 1), 24), "stride 0"),
        ("stride 0 x2, 4 TB", (0, (1 << 20, 1 << 20), (0, 0), 24), "over the limit"),
        ("size 2^31", (0, (1 << 31,), (1,), 24), "over the limit"),
        ("size 2^62", (0, (1 << 62,), (1,), 24), "over the limit"),
        ("size 2^64", (0, (1 << 64,), (1,), 24), "over the limit"),
        ("numel over the limit", (0, (4096, 4097), (4097, 1), 24), "over the limit"),
        ("negative size", (0, (-1, 3), (3, 1), 24), "geometry"),
        ("negative offset", (-1, (8, 3), (3, 1), 24), "geometry"),
        ("negative stride", (0, (8, 3), (-3, 1), 24), "geometry"),
        ("rank mismatch", (0, (8, 3), (3,), 24), "geometry"),
        ("65 dims", (0, (1,) * 65, (1,) * 65, 24), "geometry"),
        ("offset past the end", (24, (8, 3), (3, 1), 24), "past its storage"),
        ("offset 2^40", (1 << 40, (8, 3), (3, 1), 24), "past its storage"),
        ("offset by one", (1, (8, 3), (3, 1), 24), "past its storage"),
        ("stride overrun", (0, (8, 3), (4, 1), 24), "past its storage"),
        ("stride 2^40", (0, (8, 3), (3, 1 << 40), 24), "past its storage"),
        ("numel 0", (0, (8, 3), (3, 1), 0), "declares"),
        ("numel short", (0, (8, 3), (3, 1), 23), "declares"),
        ("numel long", (0, (8, 3), (3, 1), 25), "declares"),
        ("numel over the limit", (0, (8, 3), (3, 1), (64 * MiB) // 4 + 1), "over the limit"),
        ("numel 2^40", (0, (8, 3), (3, 1), 1 << 40), "over the limit"),
        ("numel 2^62", (0, (8, 3), (3, 1), 1 << 62), "over the limit"),
        ("numel -1", (0, (8, 3), (3, 1), -1), "persistent id"),
    ]


def _evil_pickles(marker: Path) -> list[bytes]:
    """Pickles that would run code (touch `marker`) under a plain unpickler."""

    class Evil:
        def __init__(self, fn, arg):
            self.fn, self.arg = fn, arg

        def __reduce__(self):
            return self.fn, (self.arg,)

    cmd = f"touch {marker}"
    evil = [pickle.dumps(Evil(os.system, cmd), protocol=p) for p in range(6)]
    evil += [pickle.dumps(Evil(exec, f"open({str(marker)!r}, 'w').close()"), protocol=p) for p in (2, 4)]
    evil += [pickle.dumps(Evil(subprocess.call, ["touch", str(marker)]), protocol=2)]
    evil += [f"(S'{cmd}'\nios\nsystem\n.".encode(), f"(cos\nsystem\nS'{cmd}'\no.".encode()]  # INST, OBJ
    for module, name in (("posix", "system"), ("os", "system"), ("builtins", "eval")):
        arg = cmd if name == "system" else f"__import__('os').system({cmd!r})"
        evil.append(_torch_zip.pickle_bytes(STATE, extra_global=(module, name, arg)))
    return evil


def _cases(folder: Path, scale: int) -> tuple[list[tuple[str, bytes, str]], Path]:
    """(name, file bytes, expected) for every case: expected is "ok", a refusal needle, or "any"."""
    rng = np.random.default_rng(15)
    pkl = _torch_zip.pickle_bytes(STATE)
    stored, deflated = _zip(_members(pkl)), _zip(_members(pkl), zipfile.ZIP_DEFLATED)
    cases = [("valid stored", stored, "ok"), ("valid deflated", deflated, "ok")]
    cases += [(f"pickle flip {i}", _zip(_members(_flip(rng, pkl, 2))), "any") for i in range(120 * scale)]
    cases += [(f"zip flip {i}", _flip(rng, stored if i % 2 else deflated), "any") for i in range(120 * scale)]
    for i in range(30 * scale):
        cut = int(rng.integers(0, len(stored)))
        cases.append((f"truncated zip {cut}", (stored if i % 2 else deflated)[:cut], "any"))
    for i in range(20 * scale):
        cases.append((f"truncated pickle {i}", _zip(_members(pkl[: int(rng.integers(0, len(pkl)))])), "refused"))
    for name, geometry, expected in _geometry_cases():
        cases.append((name, _zip(_members(_torch_zip.pickle_bytes(STATE, geometry={W: geometry}))), expected))
    # Counted opcodes the C unpickler would allocate for before reading: a 2^28 memo index
    # (4 GiB of memo table from a 10-byte pickle) and a 2 GiB byte string.
    cases += [("memo index 2^28", _zip(_members(pkl[:2] + b"Nr\xff\xff\xff\x0f0" + pkl[2:])), "memo index"),
              ("bytes 2^31", _zip(_members(pkl[:2] + b"B\xff\xff\xff\x7f" + pkl[2:])), "corrupt pickle")]
    for base_name, base in (("stored", stored), ("deflated", deflated)):
        for member in ("archive/data/0", "archive/data.pkl"):
            for usize in (0, 1, 95, 97, 64 * MiB, 64 * MiB + 4, 1 << 31, (1 << 32) - 1):
                cases.append((f"{base_name} {member} usize {usize}", _torch_zip.patch_sizes(base, member, usize), "any"))
            cases.append((f"{base_name} {member} csize 2^32-1", _torch_zip.patch_sizes(base, member, csize=(1 << 32) - 1), "any"))
    # Deflate bombs: 80 MiB of zeros in about 80 kB, declared honestly or as the tensor's 96 bytes.
    bomb = _zip(_members(pkl, bytes(80 * MiB)), zipfile.ZIP_DEFLATED)
    cases += [("bomb, honest header", bomb, "over the limit"),
              ("bomb, lying header", _torch_zip.patch_sizes(bomb, "archive/data/0", 96), "refused")]
    # The largest load the limits allow: one 60 MiB storage, deflated, copied once.
    n = 60 * MiB // 4
    fat = _torch_zip.pickle_bytes({"w": np.zeros(1, np.float32)}, geometry={"w": (0, (n,), (1,), n)})
    cases.append(("60 MiB tensor", _zip({"archive/data.pkl": fat, "archive/data/0": bytes(4 * n)}, zipfile.ZIP_DEFLATED), "ok"))
    end = stored.rfind(b"PK\x05\x06")
    for field, value in ((10, 0xFFFF), (10, 5000), (12, 0xFFFFFFFF), (12, 2 * MiB), (16, 0xFFFFFFFF)):
        b = bytearray(stored)
        struct.pack_into("<H" if field == 10 else "<L", b, end + field, value)
        cases.append((f"end record field {field} = {value}", bytes(b), "any"))
    z64 = struct.pack("<4sQ2H2L4Q", b"PK\x06\x06", 44, 45, 45, 0, 0, 1 << 40, 1 << 40, 1 << 40, 0)
    locator = struct.pack("<4sLQL", b"PK\x06\x07", 0, end, 1)
    cases.append(("zip64 record, 2^40 members", stored[:end] + z64 + locator + stored[end:], "members"))
    cases.append(("bzip2", _zip(_members(pkl), zipfile.ZIP_BZIP2), "compression method"))
    cases.append(("many members", _zip({**_members(pkl), **{f"x/{i}": b"" for i in range(5000)}}), "members"))
    marker = folder / "pwned"
    evil = _evil_pickles(marker)
    cases += [(f"evil pickle {i}", _zip(_members(p)), "refused") for i, p in enumerate(evil)]
    cases += [(f"evil flip {i}", _zip(_members(_flip(rng, evil[i % len(evil)], 2))), "any")
              for i in range(30 * scale)]
    return cases, marker


def _run_children(paths: list[str], children: int = 2) -> tuple[dict[str, list[str]], int]:
    """Each path's [outcome, message], and the worst child's peak RSS beyond its start [KiB]."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    procs = [
        subprocess.Popen([sys.executable, "-c", CHILD, str(CAP)], stdin=subprocess.PIPE,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        for _ in range(children)
    ]
    results, worst = {}, 0
    for k, proc in enumerate(procs):
        out, err = proc.communicate("\n".join(paths[k::children]), timeout=300)
        lines = [json.loads(line) for line in out.splitlines()]
        done = [line[0] for line in lines]
        assert proc.returncode == 0, f"child {k} died ({proc.returncode}) after {done[-1:]}: {err[-2000:]}"
        for path, outcome, msg in lines:
            if path == "peak_kib":
                worst = max(worst, outcome)
            else:
                results[path] = [outcome, msg]
    return results, worst


def _fuzz(tmp_path: Path, record_property, scale: int) -> None:
    cases, _ = _cases(tmp_path, scale)
    paths = []
    for i, (_name, data, _expected) in enumerate(cases):
        path = tmp_path / f"case{i:05d}.tar"
        path.write_bytes(data)
        paths.append(str(path))
    results, worst_kib = _run_children(paths)
    assert len(results) == len(cases)
    bad = []
    for (name, _data, expected), path in zip(cases, paths):
        outcome, msg = results[path]
        if outcome not in ("ok", "input_error"):
            bad.append(f"{name}: {outcome} {msg}")
        elif expected == "ok" and outcome != "ok":
            bad.append(f"{name}: expected a load, got {msg}")
        elif expected not in ("ok", "any") and (outcome != "input_error" or expected not in msg):
            bad.append(f"{name}: expected a refusal with {expected!r}, got {outcome} {msg}")
    assert not bad, "\n".join(bad[:20])
    assert not list(tmp_path.glob("pwned*")), "a tampered pickle ran code"
    # The largest case loads 60 MiB (a storage, its chunks joined, the tensor's copy): about 170
    # MiB beyond the reader's start. A bound that lets no limit (64 MiB a storage, 256 MiB in all)
    # slip unnoticed.
    assert worst_kib < 352 * 1024, f"a child peaked at {worst_kib / 1024:.0f} MiB beyond its start"
    loaded = sum(r[0] == "ok" for r in results.values())
    record_property("cases", len(cases))
    record_property("worst_child_peak_mib", round(worst_kib / 1024, 1))
    print(f"\ncheckpoint fuzz: {len(cases)} cases ({loaded} loaded, {len(cases) - loaded} refused), "
          f"worst child peak RSS {worst_kib / 1024:.0f} MiB beyond its start, under a {CAP >> 20} MiB address-space cap")


def test_hostile_checkpoints_are_refused_cleanly(tmp_path, record_property):
    _fuzz(tmp_path, record_property, scale=1)


@pytest.mark.slow
def test_hostile_checkpoints_are_refused_cleanly_thousands(tmp_path, record_property):
    _fuzz(tmp_path, record_property, scale=10)
