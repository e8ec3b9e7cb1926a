"""Property: whatever a user's file holds, the recorded-traffic readers and the TOML loaders give
a valid load or exactly one `diffsense.InputError` (one line), never another exception; scenes
loaded from a recording hold finite numbers only.

The inputs are arbitrary bytes and valid files mutated (flipped bytes, truncation, inserted junk,
a cell or value replaced by a hostile token: huge numbers, NaN, deep nesting, huge text, odd
digits, ...). Examples are few and derandomized, so a run is quick and reproducible; beside them,
two exhaustive sweeps put a huge number in every column of a recording and a hostile value in
place of every number of a shipped config."""

from __future__ import annotations

import re
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import jax
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import diffsense as ds
from diffsense.config import parse_toml
from diffsense.scene import load_recorded, load_road, load_scenario, read_highd, read_ngsim
from diffsense.sensors import load_config
from diffsense.study import load_suite
from tests._recorded_files import HIGHD_META, HIGHD_RECORDING, HIGHD_TRACKS, NGSIM, write_highd, write_ngsim

ROOT = Path(__file__).resolve().parents[1]
FEW = settings(max_examples=40, deadline=None, derandomize=True, database=None,
               suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.large_base_example])

CSV_TOKENS = ["nan", "NaN", "inf", "-inf", "1e300", "-1e300", "1e309", "1e-320", "1e19", "2e19",
              "9007199254740993", "", " ", "-0", "0", "0x1A", "1_0", "\u0661\u0662", "\x00", '"', '"a,b"',
              "a" * 140_000, "1e300;1e300", ";", "3;2;1", "\ufeff1", "1\r", "\r\n", "-"]
TOML_TOKENS = ["nan", "-nan", "inf", "-inf", "1e400", "1" + "0" * 400, "9" * 5000, "-0.0", "0", "-1", "1e-400",
               '"x"', "'", '"""', "[]", "{}", "true", "1979-05-27T07:32:00Z", "07:32:00", "1979-05-27",
               "[" * 40 + "]" * 40, "{a = " * 40 + "1" + "}" * 40, '"' + "a" * 200_000 + '"', "[1, 'a']",
               "{a = 1}", "[[1.0, 2.0], [3.0]]", '"\\u0000"', "[nan, inf]", "[1e400, 2]", "[-1e308, 1e308]"]
TOML_LINES = ["a" + ".a" * 3000 + " = 1", "[" + "a." * 3000 + "a]", "[[params]]", "[params]",
              "[[x]]\n[x]", "k = 1\nk = 2", "sensors = []", "\ufeffx = 1"]


def _refused_or_loaded(load: Callable[[], object]) -> object | None:
    """The property: `load()` returns (its value), or raises one InputError with a one-line message."""
    try:
        return load()
    except ds.InputError as e:
        assert "\n" not in str(e)
        return None


def _finite(scenes: list | None) -> None:
    """Scenes loaded from a recording hold finite numbers only (a 1e300 is refused, not an inf)."""
    for leaf in jax.tree.leaves(scenes or []):
        values = np.asarray(leaf)
        assert not np.issubdtype(values.dtype, np.floating) or np.all(np.isfinite(values))


def _field_bounds(data: bytearray, pos: int, csv: bool) -> tuple[int, int]:
    """The cell of a CSV, or the value after '=' on a TOML line, around `pos`."""
    start = data.rfind(b"\n", 0, pos) + 1
    end = data.find(b"\n", pos)
    end = len(data) if end < 0 else end
    if csv:
        comma = data.rfind(b",", start, pos)
        start = comma + 1 if comma >= 0 else start
        comma = data.find(b",", pos, end)
        return start, comma if comma >= 0 else end
    equals = data.find(b"=", start, end)
    return (equals + 1, end) if equals >= 0 else (pos, pos)


@st.composite
def mutated(draw, valid: bytes, csv: bool) -> bytes:
    """`valid` changed by one to three mutations."""
    data = bytearray(valid)
    tokens = CSV_TOKENS if csv else TOML_TOKENS
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["flip", "truncate", "insert", "token", "token", "line"]))
        pos = draw(st.integers(0, max(0, len(data) - 1)))
        if kind == "flip" and data:
            data[pos] ^= draw(st.integers(1, 255))
        elif kind == "truncate":
            del data[pos:]
        elif kind == "insert":
            data[pos:pos] = draw(st.binary(min_size=1, max_size=16) | st.sampled_from(tokens).map(str.encode))
        elif kind == "token":
            start, end = _field_bounds(data, pos, csv)
            numbers = st.floats().map(repr) | st.integers(-2**70, 2**70).map(str)
            data[start:end] = draw(st.sampled_from(tokens) | numbers).encode()
        else:  # a line deleted, doubled, or (TOML) a hostile line inserted
            start, end = data.rfind(b"\n", 0, pos) + 1, data.find(b"\n", pos) + 1 or len(data)
            how = draw(st.sampled_from(["delete", "double", "insert"]))
            line = bytes(data[start:end])
            extra = (draw(st.sampled_from(TOML_LINES)).encode() + b"\n") if not csv else line
            data[start:end] = {"delete": b"", "double": line + line, "insert": extra + line}[how]
    return bytes(data)


# -- recorded traffic ------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def highd() -> dict[str, bytes]:
    """The three sibling files of a valid small highD recording, by suffix."""
    with tempfile.TemporaryDirectory() as folder:
        write_highd(Path(folder))
        return {p.name[3:]: p.read_bytes() for p in Path(folder).iterdir()}


@pytest.fixture(scope="module")
def ngsim() -> bytes:
    with tempfile.TemporaryDirectory() as folder:
        return write_ngsim(Path(folder)).read_bytes()


def _highd_with(files: dict[str, bytes], name: str, content: bytes) -> None:
    with tempfile.TemporaryDirectory() as folder:
        for suffix, valid in files.items():
            (Path(folder) / f"01_{suffix}").write_bytes(content if suffix == name else valid)
        tracks = Path(folder) / "01_tracks.csv"
        _refused_or_loaded(lambda: read_highd(tracks))
        _finite(_refused_or_loaded(lambda: load_recorded(f"highd:{tracks}")))


def _ngsim_with(content: bytes) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "trajectories.csv"
        path.write_bytes(content)
        _refused_or_loaded(lambda: read_ngsim(path))
        _finite(_refused_or_loaded(lambda: load_recorded(f"ngsim:{path}")))


NAMES = ["tracks.csv", "tracksMeta.csv", "recordingMeta.csv"]


@FEW
@given(data=st.data())
def test_a_mutated_highd_recording_loads_or_is_refused(highd, data):
    name = data.draw(st.sampled_from(NAMES))
    _highd_with(highd, name, data.draw(mutated(highd[name], csv=True)))


@FEW
@given(name=st.sampled_from(NAMES), content=st.binary(max_size=400))
def test_arbitrary_bytes_as_a_highd_file_load_or_are_refused(highd, name, content):
    _highd_with(highd, name, content)


@FEW
@given(data=st.data())
def test_a_mutated_ngsim_recording_loads_or_is_refused(ngsim, data):
    _ngsim_with(data.draw(mutated(ngsim, csv=True)))


@FEW
@given(content=st.binary(max_size=400) | st.text(max_size=200).map(str.encode))
def test_arbitrary_bytes_as_an_ngsim_file_load_or_are_refused(content):
    _ngsim_with(content)


HUGE = ["1e300", "-1e300", "1e39", "-1e39"]  # beyond float64 squared, beyond float32
SWEEP = [*(("highd", "tracks.csv", c) for c in HIGHD_TRACKS), *(("highd", "tracksMeta.csv", c) for c in HIGHD_META),
         *(("highd", "recordingMeta.csv", c) for c in HIGHD_RECORDING), *(("ngsim", None, c) for c in NGSIM)]


def _with_cell(content: bytes, column: str, token: str) -> bytes:
    """`content` with `column` of its first and middle data rows set to `token`."""
    lines = content.decode().replace("\r\n", "\n").split("\n")
    at = lines[0].split(",").index(column)
    for row in {1, len(lines) // 2}:
        cells = lines[row].split(",")
        cells[at] = token
        lines[row] = ",".join(cells)
    return "\n".join(lines).encode()


@pytest.mark.parametrize(("kind", "name", "column"), [
    pytest.param(*case, id="-".join(c or "csv" for c in case)) for case in SWEEP])
def test_a_huge_number_in_any_cell_is_refused_or_loads_finite(highd, ngsim, kind, name, column):
    for token in HUGE:
        if kind == "highd":
            _highd_with(highd, name, _with_cell(highd[name], column, token))
        else:
            _ngsim_with(_with_cell(ngsim, column, token))


# -- TOML ------------------------------------------------------------------------------------------

LOADERS: dict[str, tuple[str, Callable[[Path], object]]] = {
    "--config": ("configs/optimise/default.toml", ds.Problem.from_toml),
    "--sensor-config radar": ("configs/sensors/radar.toml", lambda p: load_config("radar", p)),
    "--sensor-config camera": ("configs/sensors/camera.toml", lambda p: load_config("camera", p)),
    "--suite": ("configs/suites/radar_camera_mounted_d14.toml", ds.Problem.from_suite),
    "--suite laws": ("configs/suites/radar_camera_laws_d2.toml", ds.Problem.from_suite),
    "suite file": ("configs/suites/corner_radars_camera_d16.toml", load_suite),
    "scenario": ("configs/scenarios/sc03.toml", load_scenario),
    "road": ("configs/roads/us101.toml", load_road),
}


def _toml_with(load: Callable[[Path], object], content: bytes) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "user.toml"
        path.write_bytes(content)
        _refused_or_loaded(lambda: load(path))


@pytest.mark.parametrize("which", LOADERS)
@FEW
@given(data=st.data())
def test_a_mutated_toml_file_loads_or_is_refused(which, data):
    seed, load = LOADERS[which]
    _toml_with(load, data.draw(mutated((ROOT / seed).read_bytes(), csv=False)))


@pytest.mark.parametrize("which", LOADERS)
@FEW
@given(content=st.binary(max_size=300) | st.text(max_size=200).map(str.encode))
def test_arbitrary_bytes_as_a_toml_file_load_or_are_refused(which, content):
    _toml_with(LOADERS[which][1], content)


@FEW
@given(text=st.text(max_size=300) | st.sampled_from(TOML_TOKENS + TOML_LINES).map(lambda t: f"x = {t}"))
def test_parse_toml_gives_a_table_or_one_input_error(text):
    _refused_or_loaded(lambda: parse_toml(text, "text"))


HOSTILE_VALUES = ["1" + "0" * 400, "-9223372036854775809", "9" * 5000, "1e400", "nan", "-inf", "[" * 40 + "]" * 40]
NUMBER = re.compile(r"(?<=[=,\[{]) *-?\d[\d.e+-]*")  # a number right after "=", "," or an opening bracket


@pytest.mark.parametrize("which", LOADERS)
def test_a_hostile_value_in_place_of_any_number_loads_or_is_refused(which):
    seed, load = LOADERS[which]
    lines = (ROOT / seed).read_text().split("\n")
    for row, line in enumerate(lines):
        code = line.split("#")[0]
        for match in NUMBER.finditer(code):
            for value in HOSTILE_VALUES:
                changed = code[:match.start()] + " " + value + code[match.end():]
                _toml_with(load, "\n".join([*lines[:row], changed, *lines[row + 1:]]).encode())


@pytest.mark.parametrize("text", ["[" + "a." * 200_000 + "a]\nb = 1", "x = {" + "a." * 200_000 + "a = 1}"])
def test_a_key_of_many_dotted_parts_is_refused_at_once(text):
    start = time.monotonic()  # tomllib takes a minute over this 400 kB key: its parts cost it quadratic time
    with pytest.raises(ds.InputError):
        parse_toml(text, "text")
    assert time.monotonic() - start < 10
