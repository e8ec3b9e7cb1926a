"""Outputs keep their promises: a file appears whole or not at all, with the mode the umask gives;
an output set replaces the previous run's set as one, never touches the user's own files, and an
interrupted or failed set leaves the previous one as it was; a folder that cannot be written is
refused before any work, naming the path."""

from __future__ import annotations

import json
import os
import re
import stat
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from diffsense.runtime import (
    InputError,
    atomic_open,
    check_writable,
    output_set,
    save_figure,
    write_bytes,
    write_json,
)

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = "manifest.json"


def _publish(out: Path, files: dict[str, bytes]) -> None:
    with output_set(out) as staging:
        for rel, data in files.items():
            write_bytes(staging / rel, data)


def _manifest(out: Path, files, fmt="diffsense-output-set") -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / MANIFEST).write_text(json.dumps({"format": fmt, "version": 1, "files": files}))


def _tree(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_file_that_fails_half_way_leaves_the_previous_one_and_no_temporary(tmp_path):
    write_json(tmp_path / "r.json", {"b": 1, "a": [1, 2]})
    assert (tmp_path / "r.json").read_bytes() == b'{\n  "b": 1,\n  "a": [\n    1,\n    2\n  ]\n}\n'  # indented, in order
    with pytest.raises(RuntimeError), atomic_open(tmp_path / "r.json") as f:
        f.write(b"half")
        raise RuntimeError("interrupted")
    with pytest.raises(TypeError):
        write_json(tmp_path / "r.json", {"not json": object()})
    assert json.loads((tmp_path / "r.json").read_text()) == {"b": 1, "a": [1, 2]}
    assert [p.name for p in tmp_path.iterdir()] == ["r.json"]


@pytest.mark.parametrize("umask", [0o022, 0o027, 0o077])
def test_a_file_gets_the_mode_the_umask_gives(tmp_path, umask):
    old = os.umask(umask)
    try:
        write_bytes(tmp_path / "sub" / "f.bin", b"x")  # its folder made too
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "sub" / "f.bin").stat().st_mode) == 0o666 & ~umask


def test_the_mode_is_found_without_setting_the_umask_and_without_proc(tmp_path, monkeypatch):
    # Setting the umask, even for an instant, would let another thread create a file under it.
    old = os.umask(0o027)
    try:
        with monkeypatch.context() as m:
            m.setattr(os, "umask", lambda _mask: pytest.fail("the umask was set"))
            write_bytes(tmp_path / "a.bin", b"x")
        real_open = open

        def no_proc(path, *args, **kwargs):
            if str(path).startswith("/proc"):
                raise OSError(2, "No such file or directory", path)
            return real_open(path, *args, **kwargs)

        monkeypatch.setattr("builtins.open", no_proc)
        write_bytes(tmp_path / "b.bin", b"x")  # the fallback reads the umask and puts it back
        assert os.umask(0o027) == 0o027
    finally:
        os.umask(old)
    for name in ("a.bin", "b.bin"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o640


@pytest.mark.parametrize("name, magic", [("fig.png", b"\x89PNG"), ("fig.pdf", b"%PDF"), ("fig", b"\x89PNG")])
def test_a_figure_is_saved_in_the_format_of_its_suffix_with_the_options_given(tmp_path, name, magic):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(2, 1))
    try:
        save_figure(fig, tmp_path / name, dpi=50)
    finally:
        plt.close(fig)
    data = (tmp_path / name).read_bytes()
    assert data.startswith(magic)
    if magic == b"\x89PNG":  # the IHDR chunk: width and height in pixels, 2 x 1 in at 50 dpi
        assert (int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")) == (100, 50)


def test_a_set_replaces_the_previous_set_and_keeps_the_users_files(tmp_path):
    out = tmp_path / "out"
    _publish(out, {"result.json": b"1", "radar/fig.png": b"1", "radar/deep/fig.png": b"1"})
    (out / "radar" / "notes.txt").write_text("the user's")
    (out / "mine.txt").write_text("the user's")
    _publish(out, {"result.json": b"2", "camera/figs/fig.png": b"png"})
    assert _tree(out) == {"camera/figs/fig.png": b"png", "manifest.json": (out / MANIFEST).read_bytes(),
                          "mine.txt": b"the user's", "radar/notes.txt": b"the user's", "result.json": b"2"}
    assert not (out / "radar" / "deep").exists()  # emptied by the old set's files going
    assert json.loads((out / MANIFEST).read_text()) == {
        "format": "diffsense-output-set", "version": 1, "files": ["camera/figs/fig.png", "result.json"]}
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no staging left


def test_a_failed_set_leaves_the_previous_one_and_removes_a_folder_it_made(tmp_path):
    out = tmp_path / "out"
    _publish(out, {"result.json": b"1", "radar/fig.png": b"1"})
    before = _tree(out)
    with pytest.raises(RuntimeError), output_set(out) as staging:
        write_bytes(staging / "result.json", b"2")
        raise RuntimeError("the run failed")
    assert _tree(out) == before and sorted(p.name for p in out.iterdir()) == ["manifest.json", "radar", "result.json"]
    with pytest.raises(RuntimeError), output_set(tmp_path / "new" / "deeper"):
        raise RuntimeError("the run failed")
    assert not (tmp_path / "new").exists()


def test_a_file_that_would_replace_a_folder_is_refused_before_anything_changes(tmp_path):
    out = tmp_path / "out"
    _publish(out, {"result.json": b"1"})
    (out / "fig.png").mkdir()
    before = _tree(out)
    with pytest.raises(InputError, match="fig.png"):
        _publish(out, {"fig.png": b"png", "result.json": b"2"})
    assert _tree(out) == before


_INTERRUPTED = textwrap.dedent("""
    import sys
    from pathlib import Path
    from diffsense.runtime import abandon_temporaries, output_set, write_bytes
    out, new = Path(sys.argv[1]), Path(sys.argv[2])
    with output_set(out) as staging, output_set(new) as other:
        write_bytes(staging / "result.json", b"2")
        write_bytes(other / "result.json", b"2")
        with open(staging / "half.bin", "wb") as f:
            f.write(b"half")
        abandon_temporaries()  # what the signal handler does before the process ends
        import os; os._exit(130)
""")


def test_an_interrupted_set_leaves_the_previous_one_and_no_temporary(tmp_path):
    out, new = tmp_path / "out", tmp_path / "made" / "for the set"
    _publish(out, {"result.json": b"1", "radar/fig.png": b"1"})
    before = _tree(out)
    proc = subprocess.run([sys.executable, "-c", _INTERRUPTED, str(out), str(new)], cwd=ROOT, capture_output=True,
                          text=True, timeout=300, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert proc.returncode == 130, proc.stderr[-2000:]
    assert _tree(out) == before and sorted(p.name for p in out.iterdir()) == ["manifest.json", "radar", "result.json"]
    assert not (tmp_path / "made").exists()  # the folders made for the set go with it


def test_a_manifest_never_removes_what_it_has_no_claim_to(tmp_path):
    outside = tmp_path / "outside.txt"
    outside.write_text("not the set's")
    out = tmp_path / "out"
    (out / "old").mkdir(parents=True)
    (out / "old" / "a.txt").write_text("old set")
    (out / "now_a_folder").mkdir()
    (out / "now_a_folder" / "inside.txt").write_text("the user's")
    (out / "now_a_file").write_text("the user's")
    # paths outside the folder, entries that are not names, gone, now folders or under a file
    _manifest(out, [str(outside), "../outside.txt", "sub/../../outside.txt", 5, "", None, ["x"], {"f": 1},
                    "deleted.txt", "now_a_folder", "now_a_file/fig.png", "old/a.txt"])
    _publish(out, {"result.json": b"{}"})
    assert outside.read_text() == "not the set's"
    assert not (out / "old").exists()  # the one plain name listed went, its emptied folder too
    assert (out / "now_a_folder" / "inside.txt").read_text() == "the user's"
    assert (out / "now_a_file").read_text() == "the user's"
    assert json.loads((out / MANIFEST).read_text())["files"] == ["result.json"]
    other = tmp_path / "other"  # a manifest of another format is not obeyed
    _manifest(other, ["keep.txt"], fmt="someone-else")
    (other / "keep.txt").write_text("the user's")
    _publish(other, {"result.json": b"{}"})
    assert (other / "keep.txt").read_text() == "the user's"


def test_a_folder_that_cannot_be_written_is_refused_naming_the_path(tmp_path):
    check_writable(tmp_path / "new" / "deeper")  # creatable: accepted, and nothing made
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "f").write_text("x")
    with pytest.raises(InputError, match=re.escape(str(tmp_path / "f"))):
        check_writable(tmp_path / "f")
    with pytest.raises(InputError, match=re.escape(str(tmp_path / "f"))):
        check_writable(tmp_path / "f" / "out" / "deeper")
    if os.geteuid() != 0:  # root writes anywhere
        (tmp_path / "ro").mkdir(mode=0o500)
        with pytest.raises(InputError, match="ro"):
            check_writable(tmp_path / "ro" / "out")
