"""Read a published PyTorch CS-LSTM checkpoint without torch, and map it onto the NNX network.

The file is PyTorch's zip serialisation of a `state_dict`: `<root>/data.pkl` (a pickle that
rebuilds each tensor with `torch._utils._rebuild_tensor_v2(storage, offset, size, stride, ...)`,
storages named by persistent ids `('storage', FloatStorage, key, location, numel)`) and raw
little-endian float32 storages at `<root>/data/<key>`. The unpickler resolves only
`collections.OrderedDict`, `torch._utils._rebuild_tensor_v2` and `torch.FloatStorage`, each to a
harmless local stand-in; any other global is refused, so no code from the file ever runs.
"""

from __future__ import annotations

import collections
import io
import pickle
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from diffsense.errors import InputError


class _FloatStorage:
    """Stand-in for the name `torch.FloatStorage` (a marker; never instantiated)."""


def _rebuild_tensor_v2(storage, offset, size, stride, requires_grad=False, hooks=None, *rest):
    """Rebuild a tensor as a numpy array from its storage, refusing out-of-bounds views."""
    if not isinstance(storage, np.ndarray):
        raise pickle.UnpicklingError("tensor without a float storage")
    size, stride = tuple(size), tuple(stride)
    ints = all(isinstance(v, int) and v >= 0 for v in (offset, *size, *stride))
    if not ints or len(size) != len(stride):
        raise pickle.UnpicklingError(f"invalid tensor geometry size={size} stride={stride}")
    if size and min(size) > 0:
        last = offset + sum((n - 1) * s for n, s in zip(size, stride))
        if last >= storage.size:
            raise pickle.UnpicklingError("tensor view runs past its storage")
    itemsize = storage.itemsize
    view = np.lib.stride_tricks.as_strided(
        storage[offset:], shape=size, strides=tuple(s * itemsize for s in stride), writeable=False
    )
    return np.array(view)


_ALLOWED = {
    ("collections", "OrderedDict"): collections.OrderedDict,
    ("torch._utils", "_rebuild_tensor_v2"): _rebuild_tensor_v2,
    ("torch", "FloatStorage"): _FloatStorage,
}


class _Unpickler(pickle.Unpickler):
    def __init__(self, data: bytes, archive: zipfile.ZipFile, root: str):
        super().__init__(io.BytesIO(data))
        self._archive = archive
        self._root = root
        self._storages: dict[str, np.ndarray] = {}

    def find_class(self, module: str, name: str) -> Any:
        try:
            return _ALLOWED[(module, name)]
        except KeyError:
            raise pickle.UnpicklingError(f"refused global {module}.{name}") from None

    def persistent_load(self, pid: Any) -> np.ndarray:
        ok = (
            isinstance(pid, tuple)
            and len(pid) == 5
            and pid[0] == "storage"
            and pid[1] is _FloatStorage
            and isinstance(pid[2], str)
            and pid[2].isdigit()
            and isinstance(pid[4], int)
        )
        if not ok:
            raise pickle.UnpicklingError(f"refused persistent id {pid!r}")
        key, numel = pid[2], pid[4]
        if key not in self._storages:
            try:
                raw = self._archive.read(f"{self._root}/data/{key}")
            except KeyError:
                raise pickle.UnpicklingError(f"storage {key} missing from the archive") from None
            if len(raw) != 4 * numel:
                raise pickle.UnpicklingError(f"storage {key} has {len(raw)} bytes, not 4 x {numel}")
            self._storages[key] = np.frombuffer(raw, dtype="<f4")
        return self._storages[key]


def read_state_dict(path: str | Path) -> dict[str, np.ndarray]:
    """The float32 arrays of a PyTorch zip `state_dict`, by key (PyTorch layout).

    Raises InputError, one line naming the file, for anything that is not such a checkpoint.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"checkpoint not found: {path}")
    try:
        with zipfile.ZipFile(path) as archive:
            pkls = [n for n in archive.namelist() if n.endswith("/data.pkl") and n.count("/") == 1]
            if len(pkls) != 1:
                raise InputError(f"checkpoint {path}: no <root>/data.pkl (not a PyTorch zip checkpoint)")
            root = pkls[0].split("/")[0]
            obj = _Unpickler(archive.read(pkls[0]), archive, root).load()
    except InputError:
        raise
    except zipfile.BadZipFile:
        raise InputError(f"checkpoint {path}: not a zip archive (a PyTorch >= 1.6 checkpoint is one)") from None
    except Exception as e:  # noqa: BLE001 - any failure of a tampered pickle is the same refusal
        raise InputError(f"checkpoint {path}: refused: {type(e).__name__}: {e}") from None
    if not isinstance(obj, dict) or not all(
        isinstance(k, str) and isinstance(v, np.ndarray) for k, v in obj.items()
    ):
        raise InputError(f"checkpoint {path}: not a state_dict of tensors")
    return dict(obj)
