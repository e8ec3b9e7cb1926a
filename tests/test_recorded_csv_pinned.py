"""The recorded-traffic CSV reader pinned on hand-written files: which reader runs (numpy's C
parser for numbers only, the line-by-line one otherwise), the file line of every row, and each
refusal with its whole message.
"""

from __future__ import annotations

import numpy as np
import pytest

from diffsense.runtime._errors import InputError
from diffsense.scene import _recorded_csv
from diffsense.scene._recorded_csv import (
    _fast_numbers,
    _line_count,
    integers,
    read_columns,
)

PLAIN = "id, frame ,x,y\n7,1,0.5,-2\n7,2,1.5,-2.25\n8,1,1e3,4\n"


def write(tmp_path, text, name="t.csv"):
    path = tmp_path / name
    path.write_bytes(text.encode())
    return path


def test_numbers_only_go_through_numpys_reader_in_the_asked_order(tmp_path):
    path = write(tmp_path, PLAIN)
    fast = _fast_numbers(path, ("y", "id"), [3, 0])
    assert fast is not None
    cols, lines = fast
    np.testing.assert_array_equal(cols["y"], [-2.0, -2.25, 4.0])
    np.testing.assert_array_equal(cols["id"], [7.0, 7.0, 8.0])
    np.testing.assert_array_equal(lines, [2, 3, 4])
    got, got_lines = read_columns(path, ("y", "id"))  # the same through the public reader
    np.testing.assert_array_equal(got["y"], cols["y"])
    np.testing.assert_array_equal(got_lines, [2, 3, 4])
    assert got["y"].dtype == np.float64
    # Without a newline at the end the last row still counts: numpy's reader is still used.
    path = write(tmp_path, PLAIN.rstrip("\n"), "no_newline.csv")
    cols, lines = _fast_numbers(path, ("x",), [2])
    np.testing.assert_array_equal(cols["x"], [0.5, 1.5, 1000.0])
    np.testing.assert_array_equal(lines, [2, 3, 4])


def test_the_public_reader_takes_numpys_path_for_numbers_only_and_never_for_text(tmp_path, monkeypatch):
    calls = []

    def spy(*args):
        calls.append(_fast_numbers(*args))
        return calls[-1]

    monkeypatch.setattr(_recorded_csv, "_fast_numbers", spy)
    read_columns(write(tmp_path, PLAIN), ("x", "id"))
    assert len(calls) == 1 and calls[0] is not None
    read_columns(write(tmp_path, "id,name\n1,car\n", "text.csv"), ("id",), ("name",))
    assert len(calls) == 1


def test_a_quoted_text_cell_keeps_its_line_break_as_written(tmp_path):
    # The csv module needs files opened with newline="" to read a quoted CR LF as it is.
    cols, lines = read_columns(write(tmp_path, 'id,note\r\n1,"two\r\nlines"\r\n2,one\r\n'), ("id",), ("note",))
    assert cols["note"].tolist() == ["two\r\nlines", "one"]
    np.testing.assert_array_equal(lines, [3, 4])  # the file line where each row ends


@pytest.mark.parametrize("text", [
    "id,x\n1,2\n\n3,4\n",  # a blank line: line numbers would shift
    "id,x\n",  # a header alone
    "id,x\n1,nan\n",  # a cell that is not finite
    "id,x\n1,inf\n",
    "id,x\n1,abc\n",  # not a number
])
def test_files_numpys_reader_cannot_number_or_read_go_to_the_careful_reader(tmp_path, text):
    assert _fast_numbers(write(tmp_path, text), ("id", "x"), [0, 1]) is None


@pytest.mark.parametrize(("text", "count"), [("", 0), ("a", 1), ("a\n", 1), ("a\nb", 2), ("a\n\nb\n", 3)])
def test_line_count_counts_a_last_line_without_a_newline(tmp_path, text, count):
    assert _line_count(write(tmp_path, text)) == count


def test_line_count_adds_up_over_a_file_longer_than_its_one_mebibyte_chunks(tmp_path):
    path = write(tmp_path, "x\n" + "1.5\n" * 400_000)  # 1.6 MB: two chunks
    assert _line_count(path) == 400_001


def test_blank_lines_are_skipped_and_rows_keep_their_file_lines(tmp_path):
    path = write(tmp_path, "id,name,x\n\n1, car ,2.5\n  ,  ,  \n2,truck,3\n")
    cols, lines = read_columns(path, ("x", "id"), ("name",))
    np.testing.assert_array_equal(lines, [3, 5])
    np.testing.assert_array_equal(cols["x"], [2.5, 3.0])
    np.testing.assert_array_equal(cols["id"], [1.0, 2.0])
    assert cols["name"].tolist() == ["car", "truck"]  # stripped


@pytest.mark.parametrize(("text", "columns", "message"), [
    ("", ("id",), "{p}: the file is empty (expected a header line naming the columns)"),
    ("id,x\n1,2\n", ("id", "y"), "{p}, line 1: missing column 'y' in the header"),
    ("id,x\n", ("id",), "{p}: no data rows below the header"),
    ("id,x\n\n\n", ("id",), "{p}: no data rows below the header"),
    ("id,x,y\n1,2,3\n4,5\n", ("id", "y"), "{p}, line 3: 2 cells, but column 'y' is number 3 in the header"),
    ("id,x\n1,2\n3, 4x \n", ("x",), "{p}, line 3: column 'x' is not a finite number: '4x'"),
    ("id,x\n\n1,2\n3,-inf\n", ("x",), "{p}, line 4: column 'x' is not a finite number: '-inf'"),
    ("id,x\n1,1e999\n", ("id", "x"), "{p}, line 2: column 'x' is not a finite number: '1e999'"),
    ("id,x\n1,2#3\n", ("id", "x"), "{p}, line 2: column 'x' is not a finite number: '2#3'"),  # no comments
])
def test_refusals_name_the_file_line_and_column(tmp_path, text, columns, message):
    path = write(tmp_path, text)
    with pytest.raises(InputError) as e:
        read_columns(path, columns)
    assert str(e.value) == message.format(p=path)


def test_a_missing_file_is_named(tmp_path):
    with pytest.raises(InputError) as e:
        read_columns(tmp_path / "absent.csv", ("id",))
    assert str(e.value) == f"{tmp_path / 'absent.csv'}: no such file"


def test_whole_numbers_become_int64_and_a_fraction_is_named_by_its_line(tmp_path):
    path = tmp_path / "t.csv"
    got = integers(path, "id", np.array([3.0, -1.0, 0.0]), np.array([2, 3, 5]))
    assert got.dtype == np.int64 and got.tolist() == [3, -1, 0]
    with pytest.raises(InputError) as e:
        integers(path, "frame", np.array([3.0, 4.0, 4.5, 5.25]), np.array([2, 3, 5, 6]))
    assert str(e.value) == f"{path}, line 5: column 'frame' must be a whole number, got 4.5"
