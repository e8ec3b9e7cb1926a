"""Reading the columns of a recorded-traffic CSV file, with one-line errors that name file and line.

Only the standard library's `csv` and numpy: no data-frame library is needed for a few named
columns. Line numbers are those of the file (the header is line 1), so a message points at the
row a user can open in an editor.
"""

from __future__ import annotations

import contextlib
import csv
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from diffsense.runtime import InputError

EXACT_INTEGER = 2.0**53  # beyond it float64 rounds consecutive integers together


def _header(path: Path, reader, columns: Sequence[str]) -> list[int]:
    header = next(reader, None)
    if header is None:
        raise InputError(f"{path}: the file is empty (expected a header line naming the columns)")
    names = [name.strip() for name in header]
    for name in columns:
        if name not in names:
            raise InputError(f"{path}, line 1: missing column {name!r} in the header")
    return [names.index(name) for name in columns]


def _numbers(path: Path, name: str, cells: list[str], lines: np.ndarray) -> np.ndarray:
    try:
        values = np.asarray(cells, dtype=np.float64)
    except ValueError:
        values = None
    if values is not None and np.all(np.isfinite(values)):
        return values
    for cell, line in zip(cells, lines):  # the slow path only runs to name the bad cell
        try:
            ok = np.isfinite(float(cell))
        except ValueError:
            ok = False
        if not ok:
            raise InputError(f"{path}, line {line}: column {name!r} is not a finite number: {cell.strip()!r}")
    raise AssertionError("unreachable: numpy refused a column that float() accepts")


def _line_count(path: Path) -> int:
    count, last = 0, b"\n"
    with path.open("rb") as handle:
        for chunk in iter(lambda: handle.read(1 << 20), b""):
            count += chunk.count(b"\n")
            last = chunk[-1:]
    return count + (last != b"\n")


def _fast_numbers(path: Path, numeric: Sequence[str], index: list[int]):
    """All-numeric columns by numpy's C parser; None wherever the careful reader must look."""
    try:
        with warnings.catch_warnings():  # a header-only file: the careful reader refuses it
            warnings.simplefilter("ignore", UserWarning)
            data = np.loadtxt(path, delimiter=",", skiprows=1, usecols=index, dtype=np.float64,
                              ndmin=2, comments=None, encoding="utf-8-sig")
    except (ValueError, UnicodeDecodeError):  # the careful reader names the line
        return None
    rows = data.shape[0]
    # Line numbers are row + 2 only without blank lines; the careful reader counts them otherwise.
    if rows == 0 or not np.all(np.isfinite(data)) or _line_count(path) != rows + 1:
        return None
    return {name: data[:, i] for i, name in enumerate(numeric)}, np.arange(2, rows + 2)


def _first_undecodable(path: Path) -> tuple[int, int]:
    """The file line holding the first byte that is not UTF-8, and that byte (the text reader
    decodes in blocks, so its own position is not the line's)."""
    with path.open("rb") as handle:
        for number, raw in enumerate(handle, start=1):
            try:
                raw.decode("utf-8")
            except UnicodeDecodeError as e:
                return number, raw[e.start]
    raise AssertionError("unreachable: the text reader refused bytes that decode line by line")


@contextlib.contextmanager
def _rows(path: Path) -> Iterator[Any]:
    """A csv reader of `path` (UTF-8, a byte-order mark accepted) whose decoding errors and
    oversized cells become one `InputError` line naming the file and line."""
    with path.open(newline="", encoding="utf-8-sig") as handle:
        reader = csv.reader(handle)
        try:
            yield reader
        except UnicodeDecodeError:
            line, byte = _first_undecodable(path)
            raise InputError(f"{path}, line {line}: not UTF-8 text (byte 0x{byte:02x})") from None
        except csv.Error as e:  # a cell over the csv module's field limit (131,072 characters)
            raise InputError(f"{path}, line {reader.line_num}: {e}") from None


def read_columns(
    path: str | Path, numeric: Sequence[str], text: Sequence[str] = ()
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The named columns of a CSV file and the file line of each data row.

    Numeric columns come back as float64 arrays (every cell must be a finite number), text columns
    as arrays of stripped strings. Blank lines are skipped; a file without data rows is refused.
    Files of numbers only are parsed by numpy's C reader, several times faster; the line-by-line
    reader runs for text columns, files with blank lines, and to name the line of a bad cell.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    columns = list(numeric) + list(text)
    with _rows(path) as reader:
        index = _header(path, reader, columns)
    if not text:
        fast = _fast_numbers(path, numeric, index)
        if fast is not None:
            return fast
    with _rows(path) as reader:
        next(reader)
        need = max(index) + 1
        cells: list[list[str]] = [[] for _ in columns]
        lines: list[int] = []
        for row in reader:
            if not any(cell.strip() for cell in row):
                continue
            if len(row) < need:
                raise InputError(f"{path}, line {reader.line_num}: {len(row)} cells, but column "
                                 f"{columns[index.index(max(index))]!r} is number {need} in the header")
            for out, i in zip(cells, index):
                out.append(row[i])
            lines.append(reader.line_num)
    if not lines:
        raise InputError(f"{path}: no data rows below the header")
    line_numbers = np.asarray(lines)
    out = {name: _numbers(path, name, cells[i], line_numbers) for i, name in enumerate(numeric)}
    out.update({name: np.char.strip(np.asarray(cells[len(numeric) + i], dtype=str))
                for i, name in enumerate(text)})
    return out, line_numbers


def integers(path: Path, name: str, values: np.ndarray, lines: np.ndarray) -> np.ndarray:
    """A numeric column that must hold whole numbers (ids, frames, lanes), as int64: each within
    the integers a float64 holds exactly (|v| < 2^53: a text past them reads as 2^53 or beyond), so
    that two ids never read as one."""
    whole = (values == np.round(values)) & (np.abs(values) < EXACT_INTEGER)
    if not np.all(whole):
        bad = int(np.argmin(whole))
        raise InputError(f"{path}, line {lines[bad]}: column {name!r} must be a whole number below 2^53 in size, "
                         f"got {values[bad]:.17g}")
    return values.astype(np.int64)
