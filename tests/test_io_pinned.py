"""The output set's edges, each a case a user's folder can hold: a previous manifest naming files
outside the folder, of another format, or of paths that are gone, now folders or under a file; a
user's file beside an old set's; new files two folders deep; the umask read without changing it,
and the fallback when /proc cannot be read."""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

import pytest

from diffsense.runtime import _io
from diffsense.runtime._errors import InputError

MANIFEST = _io.MANIFEST


def _publish(out: Path, files: dict[str, bytes]) -> None:
    with _io.output_set(out) as staging:
        for rel, data in files.items():
            _io.write_bytes(staging / rel, data)


def _manifest(out: Path, files, fmt="diffsense-output-set") -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / MANIFEST).write_text(json.dumps({"format": fmt, "version": 1, "files": files}))


def test_a_manifest_never_removes_files_outside_the_folder(tmp_path):
    outside = tmp_path / "outside.txt"
    outside.write_text("not the set's")
    out = tmp_path / "out"
    _manifest(out, [str(outside), "../outside.txt", "sub/../../outside.txt"])
    _publish(out, {"result.json": b"{}"})
    assert outside.read_text() == "not the set's"


def test_only_strings_that_name_something_are_taken_from_a_manifest(tmp_path):
    out = tmp_path / "out"
    (out / "old").mkdir(parents=True)
    (out / "old" / "a.txt").write_text("old set")
    _manifest(out, [5, "", None, ["x"], {"f": 1}, "old/a.txt"])
    _publish(out, {"result.json": b"{}"})
    assert not (out / "old").exists()  # the one plain name listed went, its emptied folder too


def test_a_manifest_of_another_format_is_not_obeyed(tmp_path):
    out = tmp_path / "out"
    (out / "keep.txt").parent.mkdir(parents=True)
    (out / "keep.txt").write_text("the user's")
    _manifest(out, ["keep.txt"], fmt="someone-else")
    _publish(out, {"result.json": b"{}"})
    assert (out / "keep.txt").read_text() == "the user's"


def test_old_entries_that_are_gone_now_folders_or_under_a_file_do_not_stop_a_publish(tmp_path):
    out = tmp_path / "out"
    (out / "now_a_folder").mkdir(parents=True)
    (out / "now_a_folder" / "inside.txt").write_text("the user's")
    (out / "now_a_file").write_text("the user's")
    _manifest(out, ["deleted.txt", "now_a_folder", "now_a_file/fig.png"])
    _publish(out, {"result.json": b"{}"})
    assert (out / "now_a_folder" / "inside.txt").read_text() == "the user's"
    assert (out / "now_a_file").read_text() == "the user's"
    assert json.loads((out / MANIFEST).read_text())["files"] == ["result.json"]


def test_a_folder_the_user_also_uses_is_kept(tmp_path):
    out = tmp_path / "out"
    _publish(out, {"radar/deep/fig.png": b"1", "radar/fig.png": b"1"})
    (out / "radar" / "notes.txt").write_text("the user's")
    _publish(out, {"result.json": b"{}"})
    assert not (out / "radar" / "deep").exists() and not (out / "radar" / "fig.png").exists()
    assert (out / "radar" / "notes.txt").read_text() == "the user's"


def test_new_files_two_folders_deep_are_published(tmp_path):
    out = tmp_path / "out"
    _publish(out, {"result.json": b"1"})
    _publish(out, {"radar/figs/fig.png": b"png", "result.json": b"2"})
    assert (out / "radar" / "figs" / "fig.png").read_bytes() == b"png"
    assert json.loads((out / MANIFEST).read_text())["files"] == ["radar/figs/fig.png", "result.json"]


def test_a_folder_made_meanwhile_by_someone_else_is_not_claimed(tmp_path, monkeypatch):
    target = tmp_path / "made_meanwhile"
    target.mkdir()
    real_is_dir = Path.is_dir
    # The folder appears between the check and the mkdir (another process made it).
    monkeypatch.setattr(Path, "is_dir", lambda self: False if self == target else real_is_dir(self))
    assert _io._make_folders(target) == []
    monkeypatch.undo()
    assert _io._make_folders(tmp_path / "a" / "b") == [tmp_path / "a", tmp_path / "a" / "b"]


@pytest.mark.skipif(not Path("/proc/self/status").is_file(), reason="needs /proc")
@pytest.mark.parametrize("umask", [0o022, 0o027])
def test_the_mode_is_read_without_setting_the_umask(monkeypatch, umask):
    old = os.umask(umask)
    try:
        def no_umask(_mask):
            raise AssertionError("the umask is set: another thread could create a file under the wrong mask")

        monkeypatch.setattr(_io.os, "umask", no_umask)
        assert _io._file_mode() == 0o666 & ~umask
    finally:
        monkeypatch.undo()
        os.umask(old)


@pytest.mark.parametrize("umask", [0o022, 0o027, 0o077])
def test_without_proc_the_mode_comes_from_the_umask_which_is_restored(tmp_path, monkeypatch, umask):
    def no_proc(path, *args, **kwargs):
        raise OSError(2, "No such file or directory", path)

    monkeypatch.setattr(_io, "open", no_proc, raising=False)
    old = os.umask(umask)
    try:
        assert _io._file_mode() == 0o666 & ~umask
        assert os.umask(umask) == umask  # still in force after the read
        _io.write_bytes(tmp_path / "f.bin", b"x")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "f.bin").stat().st_mode) == 0o666 & ~umask


def test_the_manifest_says_what_it_is(tmp_path):
    _publish(tmp_path / "out", {"b.txt": b"b", "a/c.txt": b"c"})
    assert json.loads((tmp_path / "out" / MANIFEST).read_text()) == {
        "format": "diffsense-output-set", "version": 1, "files": ["a/c.txt", "b.txt"]}


def test_an_output_path_that_is_a_file_is_named_as_such(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(InputError) as here:
        _io.check_writable(tmp_path / "f")
    assert str(here.value) == f"output folder {tmp_path / 'f'} exists and is not a folder"
    with pytest.raises(InputError) as under:
        _io.check_writable(tmp_path / "f" / "out" / "deeper")
    assert str(under.value) == (f"output folder {tmp_path / 'f' / 'out' / 'deeper'} lies under "
                                f"{tmp_path / 'f'}, which exists and is not a folder")


def _abandon() -> None:
    """`abandon_temporaries`, then the registry's lock given back: it keeps the lock for a
    process about to end, and this one goes on."""
    _io.abandon_temporaries()
    _io._LOCK.release()


def test_abandoned_temporaries_are_removed_contents_first_whatever_is_left_of_them(tmp_path):
    made = tmp_path / "made"  # a folder made for a set, then a staging tree and a file inside it
    made.mkdir()
    staging = made / ".staging-1"
    (staging / "sub").mkdir(parents=True)
    (staging / "sub" / "fig.png").write_bytes(b"half")
    tmp_file = made / ".result.json.tmp"
    tmp_file.write_bytes(b"half")
    kept = tmp_path / "kept"  # a folder made for a set that the user has since put a file in
    kept.mkdir()
    (kept / "user.txt").write_text("the user's")
    entries = [(made, "dir"), (staging, "tree"), (tmp_file, "file"), (kept, "dir"),
               (tmp_path / "gone.tmp", "file"), (tmp_path / "gone-tree", "tree"), (tmp_path / "gone-dir", "dir")]
    for path, kind in entries:
        _io.register_temporary(path, kind)
    try:
        assert {p: k for p, k in _io._TEMPORARIES.items() if p.startswith(str(tmp_path))} == {
            str(p): k for p, k in entries}
        _abandon()  # nothing raises for the entries already gone
    finally:
        for path, _ in entries:
            _io.release_temporary(path)
    assert not made.exists()
    assert (kept / "user.txt").read_text() == "the user's"
    assert _io._TEMPORARIES == {}


def test_a_released_temporary_is_left_alone_and_a_tree_is_the_default(tmp_path):
    f = tmp_path / "published.bin"
    f.write_bytes(b"done")
    tree = tmp_path / "staging"
    (tree / "sub").mkdir(parents=True)
    (tree / "sub" / "x.bin").write_bytes(b"x")
    _io.register_temporary(tree)  # a folder and all it holds
    _io.register_temporary(f, "file")
    _io.release_temporary(f)
    _io.release_temporary(tmp_path / "never-registered")
    _abandon()
    assert f.read_bytes() == b"done" and not tree.exists()


def test_json_is_written_indented_in_the_order_given(tmp_path):
    _io.write_json(tmp_path / "r.json", {"b": 1, "a": [1, 2]})
    assert (tmp_path / "r.json").read_bytes() == b'{\n  "b": 1,\n  "a": [\n    1,\n    2\n  ]\n}\n'


@pytest.mark.parametrize("name, magic", [("fig.png", b"\x89PNG"), ("fig.pdf", b"%PDF"), ("fig", b"\x89PNG")])
def test_a_figure_is_saved_in_the_format_of_its_suffix_with_the_options_given(tmp_path, name, magic):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(2, 1))
    try:
        _io.save_figure(fig, tmp_path / name, dpi=50)
    finally:
        plt.close(fig)
    data = (tmp_path / name).read_bytes()
    assert data.startswith(magic)
    if magic == b"\x89PNG":  # the IHDR chunk: width and height in pixels, 2 x 1 in at 50 dpi
        assert (int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")) == (100, 50)
