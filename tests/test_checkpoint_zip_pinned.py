"""The checkpoint reader's zip checks pinned at their boundaries, on hand-made bytes: where it
finds the end-of-archive record (as zipfile finds it) and the directory limits it reads there, and
how it reads a member.

`tests/test_checkpoint_fuzz.py` shows that no corruption escapes as anything but a clean refusal;
here each check is shown to refuse exactly what its limit names and to let through what sits on
the limit, with the message it gives, so a check that moved (or that zipfile happened to back up)
is seen. The pickle's checks: `tests/test_checkpoint_pickle_pinned.py`.
"""

from __future__ import annotations

import io
import struct
import zipfile

import _torch_zip
import numpy as np
import pytest

from diffsense.predictors import _checkpoint as ck
from diffsense.predictors._checkpoint import _check_directory, _Refused

SIG = b"PK\x05\x06"
MiB = 1 << 20
W = np.arange(24, dtype=np.float32).reshape(8, 3)


def _end(members: int, directory: int, offset: int = 0, comment: bytes = b"") -> bytes:
    """A zip end-of-archive record (22 bytes) declaring `members` and `directory` bytes, then its
    comment."""
    return struct.pack("<4s4H2LH", SIG, 0, 0, members, members, directory, offset, len(comment)) + comment


def _zip64(members: int, directory: int, at: int, end: bytes) -> bytes:
    """A zip64 end record at byte `at` declaring `members` in `directory` bytes, its locator, then
    the 32-bit end record `end`."""
    record = struct.pack("<4sQ2H2L4Q", b"PK\x06\x06", 44, 45, 45, 0, 0, members, members, directory, 0)
    locator = struct.pack("<4sLQL", b"PK\x06\x07", 0, at, 1)
    return record + locator + end


def _refusal(data: bytes) -> str | None:
    try:
        _check_directory(io.BytesIO(data))
    except _Refused as e:
        return str(e)
    return None


def _says(members: int, directory: int) -> str:
    return (f"the zip directory declares {members} members in {directory} bytes "
            f"(limits 4096 members, 1048576 bytes)")


def test_the_limits_are_4096_members_and_1_mib_of_directory_inclusive():
    assert (ck.MAX_MEMBERS, ck.MAX_DIRECTORY_BYTES) == (4096, MiB)
    assert _refusal(b"\0" * 100 + _end(4096, MiB)) is None
    assert _refusal(b"\0" * 100 + _end(4097, 10)) == _says(4097, 10)
    assert _refusal(b"\0" * 100 + _end(3, MiB + 1)) == _says(3, MiB + 1)
    # The fields are unsigned: their largest values are the largest counts, not -1.
    assert _refusal(b"\0" * 100 + _end(0xFFFF, 10)) == _says(0xFFFF, 10)
    assert _refusal(b"\0" * 100 + _end(3, 0xFFFFFFFF)) == _says(3, 0xFFFFFFFF)


def test_a_record_behind_an_archive_comment_is_found_as_zipfile_finds_it():
    assert _refusal(_end(5000, 10, comment=b"a comment")) == _says(5000, 10)
    # A comment whose last 22 bytes end in two zero bytes, as a record with no comment would: the
    # last 22 bytes are not a record (no signature), so the record is the one before the comment.
    comment = b"\xff" * 20 + b"\0\0"
    assert _refusal(_end(3, 100, comment=comment)) is None
    assert _refusal(_end(5000, 100, comment=comment)) == _says(5000, 100)


def test_a_signature_inside_the_last_record_is_not_taken_for_a_later_record():
    # The directory's offset field spells the signature: a search from the end finds it 6 bytes
    # from the end, but the last 22 bytes are a record without a comment, and that one counts.
    offset = int.from_bytes(SIG, "little")
    assert _refusal(b"\x01" * 100 + _end(5000, 10, offset=offset)) == _says(5000, 10)


def test_the_last_record_in_the_window_counts():
    # Two records, the later one with a comment: zipfile searches from the end, and so does this.
    assert _refusal(b"\x01" * 10 + _end(5000, 10) + _end(3, 10, comment=b"c")) is None
    assert _refusal(b"\x01" * 10 + _end(3, 10) + _end(5000, 10, comment=b"c")) == _says(5000, 10)


def test_only_zipfile_s_window_is_searched():
    # zipfile looks for the record in the last 22 + 65535 bytes (a record and the longest comment).
    window = 22 + 0xFFFF
    inside = _end(5000, 10) + b"\x01" * (window - 22)
    assert len(inside) == window and _refusal(inside) == _says(5000, 10)
    assert _refusal(_end(5000, 10) + b"\x01" * (window - 21)) is None


def test_no_record_or_a_cut_one_is_left_to_zipfile():
    assert _refusal(b"") is None
    assert _refusal(b"\x01" * 100) is None
    assert _refusal(b"\x01" * 30 + SIG + b"\0" * 17) is None  # 21 bytes from the signature on


def test_a_zip64_record_replaces_the_32_bit_counts():
    marker = _end(0xFFFF, 0xFFFFFFFF)
    assert _refusal(_zip64(1 << 40, 10, 0, marker)) == _says(1 << 40, 10)
    assert _refusal(_zip64(3, 1 << 40, 0, marker)) == _says(3, 1 << 40)
    assert _refusal(_zip64(4096, MiB, 0, marker)) is None  # the 32-bit record's 0xFFFF ignored
    assert _refusal(b"\0" * 7 + _zip64(1 << 40, 10, 7, _end(3, 10))) == _says(1 << 40, 10)


def test_a_zip64_record_needs_both_signatures():
    good = _zip64(1 << 40, 10, 0, _end(3, 10))
    for at, wrong in ((0, b"PK\x06\x05"), (56, b"PK\x06\x08")):
        bad = good[:at] + wrong + good[at + 4:]
        assert _refusal(bad) is None  # the 32-bit counts, 3 members in 10 bytes, are read instead
    assert _refusal(good[1:]) is None  # the locator 55 bytes in: no room for a record before it


# --- members ------------------------------------------------------------------------------------

def _archive(members: dict[str, bytes], compression: int = zipfile.ZIP_STORED) -> zipfile.ZipFile:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression) as z:
        for name, data in members.items():
            z.writestr(name, data)
    return zipfile.ZipFile(io.BytesIO(buf.getvalue()))


def _member_refusal(archive, *args) -> str:
    with pytest.raises(_Refused) as info:
        ck._read_member(archive, *args)
    return str(info.value)


@pytest.mark.parametrize("compression", [zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED])
def test_a_member_is_read_whole_in_bounded_chunks(monkeypatch, compression):
    monkeypatch.setattr(ck, "CHUNK_BYTES", 7)  # 96 bytes in 14 chunks, the last one short
    data = W.tobytes()
    archive = _archive({"a/data/0": data}, compression)
    assert ck._read_member(archive, "a/data/0", 96, 96) == data
    assert ck._read_member(archive, "a/data/0", 96) == data  # at the limit
    assert _member_refusal(archive, "a/data/0", 95) == "a/data/0 declares 96 bytes, over the limit of 95"
    assert (_member_refusal(archive, "a/data/0", 200, 100, "storage 0: ")
            == "storage 0: a/data/0 declares 96 bytes, not the 100 its tensor needs")
    assert (_member_refusal(archive, "a/data/1", 96, None, "storage 1: ")
            == "storage 1: a/data/1 missing from the archive")


@pytest.mark.parametrize("compression, method", [(zipfile.ZIP_BZIP2, 12), (zipfile.ZIP_LZMA, 14)])
def test_members_compressed_without_an_output_bound_are_refused(compression, method):
    archive = _archive({"a/data.pkl": b"x" * 50}, compression)
    assert (_member_refusal(archive, "a/data.pkl", 100)
            == f"a/data.pkl uses compression method {method} (only stored or deflated)")


def test_a_member_holding_other_than_it_declares_is_refused(tmp_path):
    pkl = _torch_zip.pickle_bytes({"w": W})
    good = tmp_path / "good.tar"
    _torch_zip.zip_file(good, {"archive/data.pkl": pkl, "archive/data/0": W.tobytes()})
    blob = good.read_bytes()
    short = tmp_path / "short.tar"  # 96 bytes stored, 95 declared: zipfile stops at 95, its CRC fails
    short.write_bytes(_torch_zip.patch_sizes(blob, "archive/data/0", usize=95))
    with zipfile.ZipFile(short) as archive, pytest.raises(zipfile.BadZipFile, match="Bad CRC-32"):
        ck._read_member(archive, "archive/data/0", 200)
    long = tmp_path / "long.tar"  # 96 bytes stored, 100 declared
    long.write_bytes(_torch_zip.patch_sizes(blob, "archive/data/0", usize=100))
    with zipfile.ZipFile(long) as archive:
        assert (_member_refusal(archive, "archive/data/0", 200)
                == "archive/data/0 holds 96 bytes, not the 100 it declares")
