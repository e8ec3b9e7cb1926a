"""Write a PyTorch-format zip checkpoint of a state_dict without torch (for loader tests).

Emits the same pickle opcodes as torch.save of a state_dict (protocol 2): an OrderedDict whose
values are `torch._utils._rebuild_tensor_v2((storage pid), offset, size, stride, False,
OrderedDict())`, storages as persistent ids ('storage', torch.FloatStorage, key, 'cpu', numel).
`extra_global` lets a test smuggle in a call to an arbitrary global (a tampered pickle);
`geometry` overrides a tensor's (offset, size, stride, numel) as written, for hostile-geometry tests.
"""

from __future__ import annotations

import io
import struct
import zipfile

import numpy as np


# Pickle opcodes as torch.save writes them (protocol 2), for hand-made pickles.
def pickled_str(s: str) -> bytes:
    b = s.encode()
    return b"X" + struct.pack("<I", len(b)) + b


def pickled_int(i: int) -> bytes:
    if -(1 << 31) <= i < (1 << 31):
        return b"J" + struct.pack("<i", i)
    raw = i.to_bytes((i.bit_length() + 8) // 8, "little", signed=True)  # LONG1, as pickle does
    return b"\x8a" + bytes([len(raw)]) + raw


def pickled_tuple(items: list[bytes]) -> bytes:
    return b"(" + b"".join(items) + b"t"


def pickled_global(module: str, name: str) -> bytes:
    return b"c" + module.encode() + b"\n" + name.encode() + b"\n"


def pickle_bytes(sd: dict[str, np.ndarray], extra_global: tuple[str, str, str] | None = None,
                 geometry: dict[str, tuple[int, tuple, tuple, int]] | None = None) -> bytes:
    out = [b"\x80\x02", pickled_global("collections", "OrderedDict"), b")R", b"("]
    for key_id, (name, arr) in enumerate(sd.items()):
        stride = [int(np.prod(arr.shape[i + 1:])) for i in range(arr.ndim)]
        offset, shape, stride, numel = (geometry or {}).get(name, (0, arr.shape, stride, arr.size))
        pid = pickled_tuple([pickled_str("storage"), pickled_global("torch", "FloatStorage"), pickled_str(str(key_id)),
                      pickled_str("cpu"), pickled_int(numel)])
        args = pickled_tuple([pid + b"Q", pickled_int(offset), pickled_tuple([pickled_int(n) for n in shape]),
                       pickled_tuple([pickled_int(s) for s in stride]), b"\x89",
                       pickled_global("collections", "OrderedDict") + b")R"])
        out += [pickled_str(name), pickled_global("torch._utils", "_rebuild_tensor_v2"), args, b"R"]
    if extra_global is not None:  # e.g. ("posix", "system", "touch /tmp/x"): key -> call result
        module, name, arg = extra_global
        out += [pickled_str("payload"), pickled_global(module, name), pickled_tuple([pickled_str(arg)]), b"R"]
    out += [b"u", b"."]
    return b"".join(out)


def write(path, sd: dict[str, np.ndarray], extra_global=None, root: str = "archive",
          geometry=None, compression: int = zipfile.ZIP_STORED) -> None:
    with zipfile.ZipFile(path, "w", compression) as z:
        z.writestr(f"{root}/data.pkl", pickle_bytes(sd, extra_global, geometry))
        for key_id, arr in enumerate(sd.values()):
            z.writestr(f"{root}/data/{key_id}", np.ascontiguousarray(arr, "<f4").tobytes())
        z.writestr(f"{root}/version", "3\n")


def zip_file(path, members: dict[str, bytes], compression: int = zipfile.ZIP_STORED):
    """Write `members` (name -> bytes) as a zip at `path`; returns `path`."""
    with zipfile.ZipFile(path, "w", compression) as z:
        for name, data in members.items():
            z.writestr(name, data)
    return path


def patch_sizes(blob: bytes, member: str, usize: int | None = None, csize: int | None = None) -> bytes:
    """`blob` with `member`'s declared sizes rewritten in both its local and central headers."""
    b, name = bytearray(blob), member.encode()
    with zipfile.ZipFile(io.BytesIO(blob)) as z:
        local = z.getinfo(member).header_offset
    central = next(i for i in range(len(b)) if b[i:i + 4] == b"PK\x01\x02" and b[i + 46:i + 46 + len(name)] == name)
    for pos, value in ((local + 18, csize), (local + 22, usize), (central + 20, csize), (central + 24, usize)):
        if value is not None:
            struct.pack_into("<L", b, pos, value)
    return bytes(b)
