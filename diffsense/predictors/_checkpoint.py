"""Read a published PyTorch CS-LSTM checkpoint without torch, refusing hostile files before they cost.

The file is PyTorch's zip serialisation of a `state_dict`: `<root>/data.pkl` (a pickle that
rebuilds each tensor with `torch._utils._rebuild_tensor_v2(storage, offset, size, stride, ...)`,
storages named by persistent ids `('storage', FloatStorage, key, location, numel)`) and raw
little-endian float32 storages at `<root>/data/<key>`. The unpickler resolves only
`collections.OrderedDict`, `torch._utils._rebuild_tensor_v2` and `torch.FloatStorage`, each to a
harmless stand-in made afresh for every file; any other global is refused, so no code from the
file ever runs.

Limits. A corrupted or hostile file is refused with one `InputError` line naming the file, before
any allocation larger than the limits below (the published CS-LSTM checkpoints: 24 members, a
2,113-byte pickle, the largest storage 239,616 bytes, 786,019 bytes in all):
- the zip directory: at most `MAX_MEMBERS` members and `MAX_DIRECTORY_BYTES` of central directory,
  read from the end-of-archive record before the zip module parses the directory (its in-memory
  form is about 7 times the on-disk size);
- members stored or deflated only (bzip2 and lzma members decompress without an output bound);
  every member is read in chunks of `CHUNK_BYTES`, never past its declared uncompressed size;
- `data.pkl`: at most `MAX_PICKLE_BYTES`, scanned opcode by opcode (`pickletools`) before it is
  unpickled: only the opcodes a torch `state_dict` pickle uses, no counted opcode declaring more
  bytes than the pickle holds and no memo index past its length (the C unpickler allocates a
  declared length, and a memo table up to the index, before reading);
- a storage: 4 x its declared element count must equal its member's declared uncompressed size and
  be at most `MAX_STORAGE_BYTES`; all storages together at most `MAX_TOTAL_BYTES`;
- a tensor: integer geometry >= 0, stride 0 only on a dimension of size <= 1 (a broadcast view would
  copy one value into a huge array), 4 x its element count at most `MAX_STORAGE_BYTES`, its view
  inside its storage, all tensors together at most `MAX_TOTAL_BYTES`.
"""

from __future__ import annotations

import collections
import io
import math
import pickle
import pickletools
import struct
import zipfile
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from diffsense.runtime import InputError

MiB = 1 << 20
MAX_STORAGE_BYTES = 64 * MiB
MAX_TOTAL_BYTES = 256 * MiB
MAX_PICKLE_BYTES = 1 * MiB
MAX_MEMBERS = 4096
MAX_DIRECTORY_BYTES = 1 * MiB
CHUNK_BYTES = 1 * MiB
_ITEM = 4  # bytes per float32 element
_MAX_DIMS = 64  # torch's own limit on tensor dimensions

# What torch.save writes for a state_dict (protocol 2), plus the protocol-4 forms of the same.
_OPCODES = frozenset(
    "PROTO STOP MARK POP POP_MARK DUP GLOBAL STACK_GLOBAL REDUCE BUILD BINPERSID NONE NEWTRUE "
    "NEWFALSE BININT BININT1 BININT2 LONG1 BINFLOAT BINUNICODE SHORT_BINUNICODE EMPTY_DICT "
    "EMPTY_LIST EMPTY_TUPLE TUPLE TUPLE1 TUPLE2 TUPLE3 SETITEM SETITEMS APPEND APPENDS BINPUT "
    "LONG_BINPUT MEMOIZE BINGET LONG_BINGET".split()
)
_MEMO_OPS = frozenset({"BINPUT", "LONG_BINPUT", "BINGET", "LONG_BINGET"})


class _Refused(Exception):
    """A checkpoint fails one of the module's checks (the message says which)."""


def _short(obj: Any) -> str:
    text = repr(obj)
    return text if len(text) <= 60 else text[:57] + "..."


def _check_directory(fp: BinaryIO) -> None:
    """Refuse a zip whose end record declares too many members or too large a directory.

    Finds the end record the way `zipfile` does (the last 22 bytes, else the last signature in the
    final 64 KiB + 22 bytes) and reads the zip64 record where `zipfile` would use it. A file
    without an end record is left to `zipfile` to refuse.
    """
    size = fp.seek(0, io.SEEK_END)
    tail_len = min(size, 22 + 0xFFFF)
    fp.seek(size - tail_len)
    tail = fp.read(tail_len)
    plain = tail[-22:-18] == b"PK\x05\x06" and tail[-2:] == b"\0\0"  # no archive comment
    at = tail_len - 22 if plain else tail.rfind(b"PK\x05\x06")
    if at < 0 or tail_len - at < 22:
        return
    members, directory = struct.unpack("<10xHL6x", tail[at : at + 22])
    locator = size - tail_len + at - 20
    if locator >= 56:
        fp.seek(locator - 56)
        record = fp.read(76)
        if record[56:60] == b"PK\x06\x07" and record[:4] == b"PK\x06\x06":
            members, directory = struct.unpack("<32xQQ8x20x", record)
    if members > MAX_MEMBERS or directory > MAX_DIRECTORY_BYTES:
        raise _Refused(
            f"the zip directory declares {members} members in {directory} bytes "
            f"(limits {MAX_MEMBERS} members, {MAX_DIRECTORY_BYTES} bytes)"
        )


def _read_member(archive: zipfile.ZipFile, name: str, limit: int, expected: int | None = None,
                 label: str = "") -> bytes:
    """The bytes of member `name`: declared size checked first, then read in bounded chunks."""
    try:
        info = archive.getinfo(name)
    except KeyError:
        raise _Refused(f"{label}{name} missing from the archive") from None
    name = f"{label}{name}"
    if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
        raise _Refused(f"{name} uses compression method {info.compress_type} (only stored or deflated)")
    if info.file_size > limit:
        raise _Refused(f"{name} declares {info.file_size} bytes, over the limit of {limit}")
    if expected is not None and info.file_size != expected:
        raise _Refused(f"{name} declares {info.file_size} bytes, not the {expected} its tensor needs")
    chunks, got = [], 0
    with archive.open(info) as f:
        while block := f.read(min(CHUNK_BYTES, info.file_size - got + 1)):
            got += len(block)
            if got > info.file_size:
                raise _Refused(f"{name} holds more than the {info.file_size} bytes it declares")
            chunks.append(block)
    if got != info.file_size:
        raise _Refused(f"{name} holds {got} bytes, not the {info.file_size} it declares")
    return b"".join(chunks)


def _scan_pickle(data: bytes) -> None:
    """Refuse a pickle with an opcode outside `_OPCODES`, a truncated argument or a wild memo index."""
    try:
        for op, arg, _ in pickletools.genops(data):
            if op.name not in _OPCODES:
                raise _Refused(f"refused pickle opcode {op.name} (not in a state_dict)")
            if op.name in _MEMO_OPS and arg >= len(data):
                raise _Refused(f"pickle memo index {arg} past the pickle's {len(data)} bytes")
    except ValueError as e:  # genops: truncated data, unknown opcode, undecodable text
        raise _Refused(f"corrupt pickle ({_short(str(e))})") from None


class _Unpickler(pickle.Unpickler):
    """Rebuilds a state_dict from the allowed globals, counting every byte it allocates."""

    def __init__(self, data: bytes, archive: zipfile.ZipFile, root: str):
        super().__init__(io.BytesIO(data))
        self._archive = archive
        self._root = root
        self._storages: dict[str, np.ndarray] = {}
        self._bytes_in = 0  # storages read
        self._bytes_out = 0  # tensors built
        self._marker = type("FloatStorage", (), {})  # per file: a BUILD opcode cannot touch ours
        self._allowed = {
            ("collections", "OrderedDict"): collections.OrderedDict,
            ("torch._utils", "_rebuild_tensor_v2"): lambda *a: self._rebuild(*a),
            ("torch", "FloatStorage"): self._marker,
        }

    def find_class(self, module: str, name: str) -> Any:
        try:
            return self._allowed[(module, name)]
        except (KeyError, TypeError):
            raise _Refused(f"refused global {_short(module)[1:-1]}.{_short(name)[1:-1]}") from None

    def persistent_load(self, pid: Any) -> np.ndarray:
        ok = (
            isinstance(pid, tuple)
            and len(pid) == 5
            and pid[0] == "storage"
            and pid[1] is self._marker
            and isinstance(pid[2], str)
            and pid[2].isascii()
            and pid[2].isdigit()
            and type(pid[4]) is int
            and pid[4] >= 0
        )
        if not ok:
            raise _Refused(f"refused persistent id {_short(pid)}")
        key, numel = pid[2], pid[4]
        if key not in self._storages:
            if numel * _ITEM > MAX_STORAGE_BYTES:
                limit = MAX_STORAGE_BYTES // _ITEM
                raise _Refused(f"storage {key} declares {numel} elements, over the limit of {limit}")
            member = f"{self._root}/data/{key}"
            raw = _read_member(self._archive, member, MAX_STORAGE_BYTES, _ITEM * numel, f"storage {key}: ")
            self._bytes_in += len(raw)
            if self._bytes_in > MAX_TOTAL_BYTES:
                raise _Refused(f"storages exceed {MAX_TOTAL_BYTES} bytes in all")
            self._storages[key] = np.frombuffer(raw, dtype="<f4")
        return self._storages[key]

    def _rebuild(self, storage: Any, offset: Any, size: Any, stride: Any, *_rest: Any) -> np.ndarray:
        """A tensor as a float32 array copied out of its storage, after every bounds check."""
        if not isinstance(storage, np.ndarray):
            raise _Refused("a tensor without a float storage")
        geometry = (offset, size, stride)
        shaped = isinstance(size, tuple) and isinstance(stride, tuple) and len(size) == len(stride)
        if not shaped or len(size) > _MAX_DIMS:
            raise _Refused(f"invalid tensor geometry {_short(geometry)}")
        if not all(type(v) is int and v >= 0 for v in (offset, *size, *stride)):
            raise _Refused(f"invalid tensor geometry {_short(geometry)}")
        limit = MAX_STORAGE_BYTES // _ITEM
        if any(n > limit for n in size) or math.prod(size) > limit:
            raise _Refused(f"a tensor of shape {_short(size)}, over the limit of {limit} elements")
        if any(s == 0 and n > 1 for n, s in zip(size, stride)):
            raise _Refused(f"a tensor with stride 0 (shape {_short(size)}, stride {_short(stride)})")
        numel = math.prod(size)
        self._bytes_out += numel * _ITEM
        if self._bytes_out > MAX_TOTAL_BYTES:
            raise _Refused(f"tensors exceed {MAX_TOTAL_BYTES} bytes in all")
        if numel == 0:
            return np.zeros(size, np.float32)
        if offset + sum((n - 1) * s for n, s in zip(size, stride)) >= storage.size:
            raise _Refused("a tensor view runs past its storage")
        strides = tuple(s * _ITEM if n > 1 else 0 for n, s in zip(size, stride))
        view = np.lib.stride_tricks.as_strided(storage[offset:], shape=size, strides=strides, writeable=False)
        return np.array(view, dtype=np.float32)


def _load(archive: zipfile.ZipFile) -> Any:
    pkls = [n for n in archive.namelist() if n.endswith("/data.pkl") and n.count("/") == 1]
    if len(pkls) != 1:
        raise _Refused("no <root>/data.pkl (not a PyTorch zip checkpoint)")
    data = _read_member(archive, pkls[0], MAX_PICKLE_BYTES)
    _scan_pickle(data)
    return _Unpickler(data, archive, pkls[0].split("/")[0]).load()


def read_state_dict(path: str | Path) -> dict[str, np.ndarray]:
    """The float32 arrays of a PyTorch zip `state_dict`, by key (PyTorch layout).

    Raises InputError, one line naming the file, for anything that is not such a checkpoint or
    breaks a limit of the module docstring. A MemoryError is re-raised: it would mean a limit
    failed to bound an allocation, never a verdict on the file.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"checkpoint not found: {path}")
    try:
        fp = open(path, "rb")  # noqa: SIM115 - closed below; an OSError here is a read failure
    except OSError as e:
        raise InputError(f"cannot read checkpoint {path}: {e.strerror}") from None
    try:
        with fp:
            _check_directory(fp)
            try:
                archive = zipfile.ZipFile(fp)
            except zipfile.BadZipFile:
                raise _Refused("not a zip archive (a PyTorch >= 1.6 checkpoint is one)") from None
            with archive:
                obj = _load(archive)
    except _Refused as e:
        reason = str(e) if str(e).startswith(("refused", "not a zip")) else f"refused: {e}"
        raise InputError(f"checkpoint {path}: {reason}") from None
    except MemoryError:
        raise
    except Exception as e:  # noqa: BLE001 - any failure of a tampered file is the same refusal
        raise InputError(f"checkpoint {path}: refused: {type(e).__name__}: {_short(str(e))}") from None
    if not isinstance(obj, dict) or not obj or not all(
        isinstance(k, str) and isinstance(v, np.ndarray) for k, v in obj.items()
    ):
        raise InputError(f"checkpoint {path}: not a state_dict of tensors")
    return dict(obj)
