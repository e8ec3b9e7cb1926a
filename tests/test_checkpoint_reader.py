"""Reading a PyTorch checkpoint without torch (`read_state_dict`, `load_predictor`): the zip format's
round trip and hand-made bytes at the reader's limits: what sits on a limit
loads as written; what breaks one is a single InputError line naming the file and the culprit,
and no code from the file ever runs. Hostile files by the hundred: tests/test_checkpoint_fuzz.py."""

from __future__ import annotations

import struct
import zipfile

import _torch_zip
import numpy as np
import pytest
from _torch_zip import pickled_global, pickled_int, pickled_str, pickled_tuple

from diffsense.predictors import (
    init_predictor,
    load_predictor,
    read_state_dict,
    state_dict_from_model,
)
from diffsense.runtime import InputError

MiB = 1 << 20
W = np.arange(24, dtype=np.float32).reshape(8, 3)
STORAGE_LIMIT = 64 * MiB // 4  # elements of one storage or tensor


def _refused(path, *culprits) -> str:
    """The InputError of reading `path`: one line, naming the file and each culprit."""
    with pytest.raises(InputError) as info:
        read_state_dict(path)
    msg = str(info.value)
    assert "\n" not in msg and str(path) in msg, msg
    for culprit in culprits:
        assert culprit in msg, msg
    return msg


@pytest.fixture(scope="module", params=[False, True], ids=["single", "maneuver"])
def state_dict(request):
    return state_dict_from_model(init_predictor(request.param, seed=1).model())


def test_round_trip_through_the_torch_format(tmp_path, state_dict):
    path = tmp_path / "ckpt.tar"
    _torch_zip.write(path, state_dict)
    got = read_state_dict(path)
    assert list(got) == list(state_dict)
    assert all(np.array_equal(got[k], state_dict[k]) and got[k].dtype == np.float32 for k in state_dict)
    predictor = load_predictor(path)
    assert predictor.maneuvers == (state_dict["dec_lstm.weight_ih_l0"].shape[1] == 117)
    back = state_dict_from_model(predictor.model())
    assert back.keys() == state_dict.keys() and all(np.array_equal(back[k], state_dict[k]) for k in back)


def test_a_checkpoint_that_is_not_a_cslstm_is_refused_naming_the_file_and_key(tmp_path, state_dict):
    for key, sd in (("op.bias", state_dict | {"op.bias": np.zeros(4, np.float32)}),
                    ("soc_fc.weight", state_dict | {"soc_fc.weight": np.zeros((2, 2), np.float32)}),
                    ("op.bias", state_dict | {"op.bias": np.full(5, np.nan, np.float32)})):
        path = tmp_path / "c.tar"
        _torch_zip.write(path, sd)
        with pytest.raises(InputError, match=f"^{path}: .*{key}"):
            load_predictor(path)


# --- hand-made pickles ----------------------------------------------------------------------------

def _pid(key: str = "0", numel: int | bytes = 24, tag: str = "storage", extra: list[bytes] | None = None) -> bytes:
    """A storage's persistent id as torch writes it: ('storage', FloatStorage, key, 'cpu', numel)."""
    items = [pickled_str(tag), pickled_global("torch", "FloatStorage"), pickled_str(key), pickled_str("cpu"),
             pickled_int(numel) if isinstance(numel, int) else numel]
    return pickled_tuple(items + (extra or [])) + b"Q"


def _tensor(pid: bytes, offset: int, size: tuple, stride: tuple) -> bytes:
    args = [pid, pickled_int(offset), pickled_tuple([pickled_int(n) for n in size]),
            pickled_tuple([pickled_int(s) for s in stride]), b"\x89", pickled_global("collections", "OrderedDict") + b")R"]
    return pickled_global("torch._utils", "_rebuild_tensor_v2") + pickled_tuple(args) + b"R"


def _checkpoint(path, tensors: dict[str, bytes], storages: dict[str, bytes] | None = None):
    body = b"".join(pickled_str(k) + v for k, v in tensors.items())
    members = {"archive/data.pkl": b"\x80\x02" + pickled_global("collections", "OrderedDict") + b")R(" + body + b"u."}
    members |= {f"archive/data/{k}": v for k, v in (storages or {"0": W.tobytes()}).items()}
    return _torch_zip.zip_file(path, members)


def test_a_hand_made_checkpoint_loads_as_written(tmp_path):
    path = _checkpoint(tmp_path / "w.tar", {"w": _tensor(_pid(), 0, (8, 3), (3, 1)),
                                            "t": _tensor(_pid(), 1, (3, 2, 1), (1, 3, 0))})
    sd = read_state_dict(path)
    assert list(sd) == ["w", "t"] and all(v.dtype == np.float32 and v.flags.writeable for v in sd.values())
    np.testing.assert_array_equal(sd["w"], W)
    np.testing.assert_array_equal(sd["t"][:, :, 0], [[1, 4], [2, 5], [3, 6]])  # transposed view, offset 1


def test_a_tensors_geometry_at_its_limits(tmp_path):
    def load(name, offset, size, stride):
        return _checkpoint(tmp_path / f"{name}.tar", {"w": _tensor(_pid(), offset, size, stride)})

    # A view may reach its storage's last element and no further; an empty one may sit anywhere.
    assert read_state_dict(load("last", 23, (1,), (1,)))["w"].tolist() == [23.0]
    _refused(load("past", 24, (1,), (1,)), "storage")
    assert read_state_dict(load("empty", 1000, (0, 3), (3, 1)))["w"].shape == (0, 3)
    # Stride 0 only on a dimension of size 1 (a broadcast view would copy one value into a huge array).
    np.testing.assert_array_equal(read_state_dict(load("ok", 0, (8, 1, 3), (3, 0, 1)))["w"][:, 0, :], W)
    _refused(load("bad", 0, (8, 2), (3, 0)), "stride 0")
    # 64 dimensions, as torch's own limit; negative numbers are no geometry.
    assert read_state_dict(load("64", 5, (1,) * 64, (1,) * 64))["w"].reshape(-1).tolist() == [5.0]
    for name, geometry in (("65", (5, (1,) * 65, (1,) * 65)), ("negative", (0, (-1, 3), (3, 1)))):
        _refused(load(name, *geometry), "geometry")
    # 64 MiB of float32 per tensor, per dimension and in all, refused before anything is allocated.
    for size, stride in (((STORAGE_LIMIT + 1,), (1,)), ((4097, 4097), (4097, 1))):
        _refused(load(f"big{len(size)}", 0, size, stride), "over the limit")


def test_a_storage_is_limited_before_its_member_is_read(tmp_path):
    _refused(_checkpoint(tmp_path / "over.tar", {"w": _tensor(_pid(numel=STORAGE_LIMIT + 1), 0, (8, 3), (3, 1))}),
             "storage 0", str(STORAGE_LIMIT + 1))
    # At the limit the count passes, and the 96-byte member is not the 64 MiB it declares.
    _refused(_checkpoint(tmp_path / "at.tar", {"w": _tensor(_pid(numel=STORAGE_LIMIT), 0, (8, 3), (3, 1))}),
             "archive/data/0", str(64 * MiB))
    _refused(_checkpoint(tmp_path / "gone.tar", {"w": _tensor(_pid(key="7"), 0, (8, 3), (3, 1))}), "archive/data/7")


_PIDS = {
    "tag": _pid(tag="storagex"),
    "class": pickled_tuple([pickled_str("storage"), pickled_global("collections", "OrderedDict"), pickled_str("0"),
                            pickled_str("cpu"), pickled_int(24)]) + b"Q",
    "key letters": _pid(key="a"),
    "key digit not ASCII": _pid(key="\u0661"),  # an Arabic-Indic one: str.isdigit, not ASCII
    "class None": pickled_tuple([pickled_str("storage"), b"N", pickled_str("0"), pickled_str("cpu"), pickled_int(24)]) + b"Q",
    "numel float": _pid(numel=b"G@8\x00\x00\x00\x00\x00\x00"),  # 24.0
    "numel bool": _pid(numel=b"\x88"),  # True: a bool, not an int
    "numel negative": _pid(numel=-1),
    "six fields": _pid(extra=[b"N"]),
    "one field": pickled_tuple([pickled_str("storage")]) + b"Q",
    "not a tuple": pickled_str("storage") + b"Q",
}


@pytest.mark.parametrize("pid", _PIDS.values(), ids=_PIDS.keys())
def test_a_persistent_id_must_be_a_float_storages(tmp_path, pid):
    # Each of these, let through, would load (a float or a longer tuple) or be refused later for
    # something else (a missing member, a size mismatch): the refusal must name the id.
    _refused(_checkpoint(tmp_path / "pid.tar", {"w": _tensor(pid, 0, (8, 3), (3, 1))}), "persistent id")


def test_a_tensor_needs_a_float_storage(tmp_path):
    args = [pickled_str("x"), pickled_int(0), pickled_tuple([pickled_int(1)]), pickled_tuple([pickled_int(1)])]
    rebuild = pickled_global("torch._utils", "_rebuild_tensor_v2") + pickled_tuple(args) + b"R"
    _refused(_checkpoint(tmp_path / "s.tar", {"w": rebuild}), "float storage")


def test_code_in_a_pickle_is_refused_and_never_runs(tmp_path, state_dict):
    marker = tmp_path / "pwned"
    for module, name, arg in (("posix", "system", f"touch {marker}"), ("builtins", "eval", "1+1")):
        path = tmp_path / f"{name}.tar"
        _torch_zip.write(path, state_dict, extra_global=(module, name, arg))
        _refused(path, f"{module}.{name}")
        with pytest.raises(InputError, match="refused"):
            load_predictor(path)
    assert not marker.exists()


@pytest.mark.parametrize("opcode, pickled", [("FRAME", b"\x80\x04\x95" + struct.pack("<Q", 1) + b"."),
                                             ("SHORT_BINBYTES", b"\x80\x02C\x01x."),
                                             ("memo index", b"\x80\x02h\x05."), ("corrupt", b"\x80\x02X\x05\x00\x00\x00ab")])
def test_a_pickle_is_scanned_before_it_is_unpickled(tmp_path, opcode, pickled):
    # Opcodes a state_dict never has, a memo index past the pickle's end (the C unpickler would
    # allocate a memo table up to it), a truncated argument.
    _refused(_torch_zip.zip_file(tmp_path / "p.tar", {"a/data.pkl": pickled}), opcode)


@pytest.mark.parametrize("pickled", [b"\x80\x02].", b"\x80\x02}.", b"\x80\x02}K\x01K\x02s.",
                                     b"\x80\x02}X\x01\x00\x00\x00aK\x02s."],
                         ids=["list", "empty", "int key", "int value"])
def test_anything_but_a_dict_of_tensors_is_refused(tmp_path, pickled):
    _refused(_torch_zip.zip_file(tmp_path / "x.tar", {"a/data.pkl": pickled}), "state_dict")


def test_what_is_not_a_checkpoint_is_refused_naming_the_file(tmp_path):
    for missing in (tmp_path / "missing.tar", tmp_path):  # nothing there, a folder
        _refused(missing, "not found")
    (tmp_path / "text.tar").write_text("not a zip")
    _refused(tmp_path / "text.tar", "zip")
    for name, members in (("none", {"a/readme": b"hi"}), ("two", {"a/data.pkl": b".", "b/data.pkl": b"."}),
                          ("deep", {"a/b/data.pkl": b"."})):
        _refused(_torch_zip.zip_file(tmp_path / f"{name}.tar", members), "data.pkl")
    # A failure inside the unpickler that no check names: its type, still one line.
    reduce_bad = b"\x80\x02" + pickled_global("collections", "OrderedDict") + b"K\x01K\x02K\x03\x87R."
    _refused(_torch_zip.zip_file(tmp_path / "reduce.tar", {"a/data.pkl": reduce_bad}), "TypeError")


# --- the zip ------------------------------------------------------------------------------------

def _padded_archive(path, members: int, directory_bytes: int, comment: bytes = b""):
    """A valid checkpoint of `members` members whose central directory is `directory_bytes` long
    (46 bytes per entry and its name): W's storage, the pickle, and empty members padding it."""
    core = {"archive/data.pkl": _torch_zip.pickle_bytes({"w": W}), "archive/data/0": W.tobytes()}
    pads = members - len(core)
    names = directory_bytes - 46 * members - sum(map(len, core))  # name bytes left for the pads
    base, extra = divmod(names, pads)
    files = dict(core)
    for i in range(pads):
        stem = f"archive/pad/{i:04d}"
        files[stem + "x" * (base + (i < extra) - len(stem))] = b""
    _torch_zip.zip_file(path, files)
    if comment:
        with zipfile.ZipFile(path, "a") as z:
            z.comment = comment
    data = path.read_bytes()
    end = data.rfind(b"PK\x05\x06")
    assert struct.unpack("<HL", data[end + 10:end + 16]) == (members, directory_bytes)  # as built
    return path


def test_the_zip_directory_is_limited_to_4096_members_and_1_mib(tmp_path):
    # Read from the end record before the zip module parses the directory (about 7 times its size
    # in memory); an archive comment does not hide the record.
    for comment in (b"", b"a comment"):
        at_limit = _padded_archive(tmp_path / "at.tar", 4096, MiB, comment)
        np.testing.assert_array_equal(read_state_dict(at_limit)["w"], W)
        _refused(_padded_archive(tmp_path / "members.tar", 4097, 300_000, comment), "4097 members")
        _refused(_padded_archive(tmp_path / "bytes.tar", 4096, MiB + 1, comment), f"{MiB + 1} bytes")


@pytest.mark.parametrize("compression", [zipfile.ZIP_BZIP2, zipfile.ZIP_LZMA])
def test_members_compressed_without_an_output_bound_are_refused(tmp_path, compression):
    members = {"archive/data.pkl": _torch_zip.pickle_bytes({"w": W}), "archive/data/0": W.tobytes()}
    _refused(_torch_zip.zip_file(tmp_path / "c.tar", members, compression), "compression method")


@pytest.mark.parametrize("declared", [95, 100])
def test_a_member_holding_other_than_it_declares_is_refused(tmp_path, declared):
    good = _torch_zip.zip_file(tmp_path / "good.tar", {"archive/data.pkl": _torch_zip.pickle_bytes({"w": W}),
                                                       "archive/data/0": W.tobytes()})
    np.testing.assert_array_equal(read_state_dict(good)["w"], W)
    bad = tmp_path / "bad.tar"  # 96 bytes stored
    bad.write_bytes(_torch_zip.patch_sizes(good.read_bytes(), "archive/data/0", usize=declared))
    _refused(bad, "archive/data/0")
