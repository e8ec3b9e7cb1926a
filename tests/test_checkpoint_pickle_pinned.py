"""The checkpoint reader's pickle checks pinned at their boundaries, on hand-made bytes: the
opcodes and memo indices it scans for, the persistent ids and tensor geometries it accepts, the
totals it counts, and the one-line refusal that names the file.

Each check is shown to refuse exactly what its limit names and to let through what sits on the
limit, with the message it gives. The zip checks: `tests/test_checkpoint_zip_pinned.py`.
"""

from __future__ import annotations

import pickletools
import struct

import _torch_zip
import numpy as np
import pytest

from diffsense.runtime._errors import InputError
from diffsense.predictors import _checkpoint as ck
from diffsense.predictors import read_state_dict
from diffsense.predictors._checkpoint import _Refused

W = np.arange(24, dtype=np.float32).reshape(8, 3)


def _pid(key: str = "0", numel: int = 24, tag: str = "storage", extra: list[bytes] | None = None) -> bytes:
    """A storage's persistent id as torch writes it: ('storage', FloatStorage, key, 'cpu', numel)."""
    items = [_torch_zip._unicode(tag), _torch_zip._global("torch", "FloatStorage"), _torch_zip._unicode(key),
             _torch_zip._unicode("cpu"), _torch_zip._int(numel) if isinstance(numel, int) else numel]
    return _torch_zip._tuple(items + (extra or [])) + b"Q"


def _tensor(pid: bytes, offset: int, size: tuple, stride: tuple) -> bytes:
    args = [pid, _torch_zip._int(offset), _torch_zip._tuple([_torch_zip._int(n) for n in size]),
            _torch_zip._tuple([_torch_zip._int(s) for s in stride]), b"\x89",
            _torch_zip._global("collections", "OrderedDict") + b")R"]
    return _torch_zip._global("torch._utils", "_rebuild_tensor_v2") + _torch_zip._tuple(args) + b"R"


def _state_pickle(tensors: dict[str, bytes]) -> bytes:
    body = b"".join(_torch_zip._unicode(k) + v for k, v in tensors.items())
    return b"\x80\x02" + _torch_zip._global("collections", "OrderedDict") + b")R(" + body + b"u."


def _checkpoint(path, tensors: dict[str, bytes], storages: dict[str, bytes] | None = None):
    members = {"archive/data.pkl": _state_pickle(tensors)}
    members |= {f"archive/data/{k}": v for k, v in (storages or {"0": W.tobytes()}).items()}
    return _torch_zip.zip_file(path, members)


def _refused_as(path, reason: str) -> None:
    with pytest.raises(InputError) as info:
        read_state_dict(path)
    assert str(info.value) == f"checkpoint {path}: {reason}"


def test_a_hand_made_checkpoint_loads_as_written(tmp_path):
    path = _checkpoint(tmp_path / "w.tar", {"w": _tensor(_pid(), 0, (8, 3), (3, 1)),
                                            "t": _tensor(_pid(), 1, (3, 2, 1), (1, 3, 0))})
    sd = read_state_dict(path)
    assert list(sd) == ["w", "t"] and all(v.dtype == np.float32 and v.flags.writeable for v in sd.values())
    np.testing.assert_array_equal(sd["w"], W)
    np.testing.assert_array_equal(sd["t"][:, :, 0], [[1, 4], [2, 5], [3, 6]])  # transposed view, offset 1


def test_a_view_may_reach_the_storage_s_last_element_and_no_further(tmp_path):
    last = _checkpoint(tmp_path / "last.tar", {"w": _tensor(_pid(), 23, (1,), (1,))})
    assert read_state_dict(last)["w"].tolist() == [23.0]
    _refused_as(_checkpoint(tmp_path / "past.tar", {"w": _tensor(_pid(), 24, (1,), (1,))}),
                "refused: a tensor view runs past its storage")
    empty = _checkpoint(tmp_path / "empty.tar", {"w": _tensor(_pid(), 1000, (0, 3), (3, 1))})
    assert read_state_dict(empty)["w"].shape == (0, 3)


def test_stride_0_is_allowed_only_on_a_dimension_of_size_1(tmp_path):
    ok = _checkpoint(tmp_path / "ok.tar", {"w": _tensor(_pid(), 0, (8, 1, 3), (3, 0, 1))})
    np.testing.assert_array_equal(read_state_dict(ok)["w"][:, 0, :], W)
    _refused_as(_checkpoint(tmp_path / "bad.tar", {"w": _tensor(_pid(), 0, (8, 2), (3, 0))}),
                "refused: a tensor with stride 0 (shape (8, 2), stride (3, 0))")


def test_a_tensor_may_have_64_dimensions_as_torch_s_may(tmp_path):
    ok = _checkpoint(tmp_path / "64.tar", {"w": _tensor(_pid(), 5, (1,) * 64, (1,) * 64)})
    assert read_state_dict(ok)["w"].reshape(-1).tolist() == [5.0]
    geometry = (5, (1,) * 65, (1,) * 65)
    _refused_as(_checkpoint(tmp_path / "65.tar", {"w": _tensor(_pid(), *geometry)}),
                f"refused: invalid tensor geometry {ck._short(geometry)}")


def test_a_tensor_s_elements_are_limited_per_dimension_and_in_all(tmp_path, monkeypatch):
    monkeypatch.setattr(ck, "MAX_STORAGE_BYTES", 96)  # 24 elements
    ok = _checkpoint(tmp_path / "ok.tar", {"w": _tensor(_pid(), 0, (24,), (1,))})
    assert read_state_dict(ok)["w"].size == 24
    for size, stride in (((25,), (1,)), ((5, 5), (5, 1))):
        path = _checkpoint(tmp_path / f"{len(size)}.tar", {"w": _tensor(_pid(), 0, size, stride)})
        _refused_as(path, f"refused: a tensor of shape {size}, over the limit of 24 elements")


def test_storages_and_tensors_are_counted_against_the_total_separately(tmp_path, monkeypatch):
    two = {"0": W.tobytes(), "1": W.tobytes()}
    separate = {"a": _tensor(_pid("0"), 0, (24,), (1,)), "b": _tensor(_pid("1"), 0, (24,), (1,))}
    shared = {"a": _tensor(_pid("0"), 0, (24,), (1,)), "b": _tensor(_pid("0"), 0, (24,), (1,))}
    monkeypatch.setattr(ck, "MAX_TOTAL_BYTES", 192)
    assert len(read_state_dict(_checkpoint(tmp_path / "at.tar", separate, two))) == 2
    monkeypatch.setattr(ck, "MAX_TOTAL_BYTES", 191)
    _refused_as(_checkpoint(tmp_path / "s.tar", separate, two), "refused: storages exceed 191 bytes in all")
    # One storage read once (96 bytes in), two tensors built from it (192 bytes out).
    _refused_as(_checkpoint(tmp_path / "t.tar", shared), "refused: tensors exceed 191 bytes in all")


def test_a_storage_is_limited_before_its_member_is_read(tmp_path):
    limit = ck.MAX_STORAGE_BYTES // 4
    _refused_as(_checkpoint(tmp_path / "over.tar", {"w": _tensor(_pid(numel=limit + 1), 0, (8, 3), (3, 1))}),
                f"refused: storage 0 declares {limit + 1} elements, over the limit of {limit}")
    _refused_as(_checkpoint(tmp_path / "at.tar", {"w": _tensor(_pid(numel=limit), 0, (8, 3), (3, 1))}),
                f"refused: storage 0: archive/data/0 declares 96 bytes, not the {4 * limit} its tensor needs")
    _refused_as(_checkpoint(tmp_path / "gone.tar", {"w": _tensor(_pid(key="7"), 0, (8, 3), (3, 1))}),
                "refused: storage 7: archive/data/7 missing from the archive")


def _pid_as(items: list[bytes]) -> bytes:
    return _torch_zip._tuple(items) + b"Q"


_U, _G, _I = _torch_zip._unicode, _torch_zip._global, _torch_zip._int
_PIDS = {
    "tag": _pid(tag="storagex"),
    "class": _pid_as([_U("storage"), _G("collections", "OrderedDict"), _U("0"), _U("cpu"), _I(24)]),
    "key letters": _pid(key="a"),
    "key digit not ASCII": _pid(key="\u0661"),  # an Arabic-Indic one: str.isdigit, not ASCII
    "class None": _pid_as([_U("storage"), b"N", _U("0"), _U("cpu"), _I(24)]),
    "numel float": _pid(numel=b"G@8\x00\x00\x00\x00\x00\x00"),  # 24.0
    "numel bool": _pid(numel=b"\x88"),  # True: a bool, not an int
    "numel negative": _pid(numel=-1),
    "six fields": _pid(extra=[b"N"]),
    "one field": _pid_as([_U("storage")]),
    "not a tuple": _U("storage") + b"Q",
}


@pytest.mark.parametrize("pid", _PIDS.values(), ids=_PIDS.keys())
def test_a_persistent_id_must_be_a_float_storage_s(tmp_path, pid):
    # Each of these, let through, would load (a float or a longer tuple) or be refused later for
    # something else (a missing member, a size mismatch): the refusal must be this one.
    path = _checkpoint(tmp_path / "pid.tar", {"w": _tensor(pid, 0, (8, 3), (3, 1))})
    with pytest.raises(InputError, match=f"checkpoint {path}: refused persistent id "):
        read_state_dict(path)


def test_a_refused_persistent_id_is_shown_cut_to_60_characters(tmp_path):
    path = _checkpoint(tmp_path / "pid.tar", {"w": _tensor(_PIDS["tag"], 0, (8, 3), (3, 1))})
    shown = "('storagex', <class 'diffsense.predictors._checkpoint.FloatStorage'>, '0', 'cpu', 24)"
    _refused_as(path, f"refused persistent id {shown[:57]}...")


def test_a_tensor_needs_a_float_storage(tmp_path):
    args = [_torch_zip._unicode("x"), _torch_zip._int(0), _torch_zip._tuple([_torch_zip._int(1)]),
            _torch_zip._tuple([_torch_zip._int(1)])]
    rebuild = _torch_zip._global("torch._utils", "_rebuild_tensor_v2") + _torch_zip._tuple(args) + b"R"
    _refused_as(_checkpoint(tmp_path / "s.tar", {"w": rebuild}), "refused: a tensor without a float storage")


# --- the pickle -----------------------------------------------------------------------------------

def _scan_refusal(data: bytes) -> str | None:
    try:
        ck._scan_pickle(data)
    except _Refused as e:
        return str(e)
    return None


def test_memo_indices_must_lie_inside_the_pickle():
    for op, pack in ((b"h", "<B"), (b"q", "<B"), (b"j", "<I"), (b"r", "<I")):  # BINGET BINPUT LONG_*
        size = 2 + 1 + struct.calcsize(pack) + 1
        inside = b"\x80\x02" + op + struct.pack(pack, size - 1) + b"."
        past = b"\x80\x02" + op + struct.pack(pack, size) + b"."
        assert _scan_refusal(inside) is None, op
        assert _scan_refusal(past) == f"pickle memo index {size} past the pickle's {size} bytes", op


def test_only_a_state_dict_s_opcodes_pass():
    assert _scan_refusal(_torch_zip.pickle_bytes({"w": W})) is None
    frame = b"\x80\x04\x95" + struct.pack("<Q", 1) + b"."
    assert _scan_refusal(frame) == "refused pickle opcode FRAME (not in a state_dict)"
    assert _scan_refusal(b"\x80\x02C\x01x.") == "refused pickle opcode SHORT_BINBYTES (not in a state_dict)"
    assert _scan_refusal(b"\x80\x02X\x05\x00\x00\x00ab").startswith("corrupt pickle (")
    # Every allowed opcode, each in a pickle of its own kind (protocol 2 and 4 forms).
    allowed = (b"\x80\x02N\x88\x89K\x01M\x01\x01J\x01\x00\x00\x00\x8a\x01\x01G?\xf0\x00\x00\x00\x00\x00\x00"
               b"X\x01\x00\x00\x00a\x8c\x01a}](t\x85\x86\x87h\x00j\x00\x00\x00\x00q\x00r\x00\x00\x00\x00\x94"
               b")0(12uaeQ\x93Rbsc\x00\n\x00\n.")
    ops = {op.name for op, _, _ in pickletools.genops(allowed)}
    assert ops == ck._OPCODES and _scan_refusal(allowed) is None


# --- the whole file -------------------------------------------------------------------------------

def test_every_refusal_is_one_line_naming_the_file(tmp_path, monkeypatch):
    missing = tmp_path / "missing.tar"
    with pytest.raises(InputError, match=f"^checkpoint not found: {missing}$"):
        read_state_dict(missing)
    with pytest.raises(InputError, match=f"^checkpoint not found: {tmp_path}$"):
        read_state_dict(tmp_path)
    text = tmp_path / "text.tar"
    text.write_text("not a zip")
    _refused_as(text, "not a zip archive (a PyTorch >= 1.6 checkpoint is one)")
    no_pkl = "refused: no <root>/data.pkl (not a PyTorch zip checkpoint)"
    for name, members in (("none", {"a/readme": b"hi"}), ("two", {"a/data.pkl": b".", "b/data.pkl": b"."}),
                          ("deep", {"a/b/data.pkl": b"."})):
        _refused_as(_torch_zip.zip_file(tmp_path / f"{name}.tar", members), no_pkl)
    evil = tmp_path / "evil.tar"
    _torch_zip.write(evil, {"w": W}, extra_global=("posix", "system", "true"))
    _refused_as(evil, "refused global posix.system")
    frame = b"\x80\x04\x95" + struct.pack("<Q", 1) + b"."
    _refused_as(_torch_zip.zip_file(tmp_path / "frame.tar", {"a/data.pkl": frame}),
                "refused pickle opcode FRAME (not in a state_dict)")
    # A failure inside the unpickler that no check names: its type and message, still one line.
    reduce_bad = b"\x80\x02" + _torch_zip._global("collections", "OrderedDict") + b"K\x01K\x02K\x03\x87R."
    with pytest.raises(InputError, match=f"^checkpoint {tmp_path / 'reduce.tar'}: refused: TypeError: "):
        read_state_dict(_torch_zip.zip_file(tmp_path / "reduce.tar", {"a/data.pkl": reduce_bad}))


@pytest.mark.parametrize("pickled", [b"\x80\x02].", b"\x80\x02}.", b"\x80\x02}K\x01K\x02s.",
                                     b"\x80\x02}X\x01\x00\x00\x00aK\x02s."],
                         ids=["list", "empty", "int key", "int value"])
def test_anything_but_a_dict_of_tensors_is_refused(tmp_path, pickled):
    _refused_as(_torch_zip.zip_file(tmp_path / "x.tar", {"a/data.pkl": pickled}),
                "not a state_dict of tensors")


def test_a_memory_error_is_not_taken_for_a_bad_file(tmp_path, monkeypatch):
    def exhausted(archive):
        raise MemoryError

    monkeypatch.setattr(ck, "_load", exhausted)
    with pytest.raises(MemoryError):
        read_state_dict(_checkpoint(tmp_path / "w.tar", {"w": _tensor(_pid(), 0, (8, 3), (3, 1))}))
