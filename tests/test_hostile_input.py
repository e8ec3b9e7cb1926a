"""Hostile input on the surfaces a user feeds files and values to, each refused by one clear
`InputError` (one `error:` line and exit 2 on the command line), never a traceback or a hang:

- recorded CSVs with bytes that are not UTF-8 or a cell over the csv module's field limit; a UTF-8
  byte-order mark is accepted;
- TOML nested past any config's depth, and paths that are not regular files (a FIFO would block
  the run forever), for `--sensor-config`, `--suite` and `--config`;
- a coordinator address without a port;
- long options are never matched by a prefix, and an error line echoing a huge value is cut to a
  screen;
- result files are strict JSON (a non-finite number is null, never `Infinity`);
- the Python API refuses a value E cannot be computed at, and an E^2 that is NaN is not 0.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import diffsense as ds
from diffsense.config import parse_toml
from diffsense.metrics import safe_sqrt
from diffsense.runtime import InputError, read_text_file, write_json
from diffsense.scene import read_highd
from tests._recorded_files import write_highd

ROOT = Path(__file__).resolve().parents[1]
DEEP = "x = " + "[" * 200 + "]" * 200 + "\n"


def _cli(*args, timeout=120):
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "diffsense.optimise", *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout)
    return done, time.perf_counter() - t0


def _refused(done, needle: str, out: Path | None = None) -> None:
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2, done.stderr[-2000:]
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0], done.stderr[-2000:]
    if out is not None:
        assert not out.exists() or not any(out.iterdir())


# -- recorded CSVs ---------------------------------------------------------------------------------

def _corrupt(path: Path, line: int, old: bytes, new: bytes) -> None:
    rows = path.read_bytes().split(b"\n")
    assert old in rows[line - 1]
    rows[line - 1] = rows[line - 1].replace(old, new, 1)
    path.write_bytes(b"\n".join(rows))


def test_a_recording_that_is_not_utf8_is_refused_naming_file_and_line(tmp_path):
    tracks = write_highd(tmp_path)
    _corrupt(tracks, 5, b",", b"\xe9,")  # a Latin-1 byte in a cell
    with pytest.raises(InputError, match=r"01_tracks\.csv.*line 5.*not UTF-8.*0xe9"):
        read_highd(tracks)


def test_a_cell_over_the_field_limit_is_refused(tmp_path):
    tracks = write_highd(tmp_path)
    meta = tmp_path / "01_recordingMeta.csv"
    _corrupt(meta, 2, b"Tue", b"T" * 200_000)  # an unused text column
    with pytest.raises(InputError, match=r"01_recordingMeta\.csv, line 2: field larger than field limit"):
        read_highd(tracks)


def test_a_byte_order_mark_is_accepted(tmp_path):
    plain = read_highd(write_highd(tmp_path))
    folder = tmp_path / "bom"
    folder.mkdir()
    tracks = write_highd(folder)
    for name in ("01_tracks.csv", "01_tracksMeta.csv", "01_recordingMeta.csv"):
        (folder / name).write_bytes(b"\xef\xbb\xbf" + (folder / name).read_bytes())
    with_bom = read_highd(tracks)
    assert with_bom.frame_rate_hz == plain.frame_rate_hz
    assert [t.vehicle_id for t in with_bom.tracks] == [t.vehicle_id for t in plain.tracks]
    assert all(np.array_equal(a.s_m, b.s_m) for a, b in zip(with_bom.tracks, plain.tracks))


# -- TOML and paths ------------------------------------------------------------------------------------

def test_toml_nested_deeper_than_any_config_is_refused_before_parsing():
    with pytest.raises(InputError, match="nested more than"):
        parse_toml(DEEP, "deep.toml")
    with pytest.raises(InputError, match="nested more than"):
        parse_toml("x = " + "{a = " * 100 + "1" + "}" * 100, "inline.toml")
    # brackets inside strings and comments, and table headers, are not nesting
    text = 's = "' + "[" * 100 + '"\n# ' + "{" * 100 + "\n[a.b]\n[[c]]\nd = [[1, 2], [3]]\n"
    assert parse_toml(text, "fine.toml") == {"s": "[" * 100, "a": {"b": {}}, "c": [{"d": [[1, 2], [3]]}]}


def test_a_fifo_a_folder_and_non_utf8_text_are_refused_at_once(tmp_path):
    fifo = tmp_path / "pipe.toml"
    os.mkfifo(fifo)
    t0 = time.perf_counter()
    with pytest.raises(InputError, match="not a regular file"):
        read_text_file(fifo, "config file")
    assert time.perf_counter() - t0 < 1.0  # never waits for a writer
    with pytest.raises(InputError, match="not a regular file"):
        read_text_file(tmp_path, "suite")
    bad = tmp_path / "latin1.toml"
    bad.write_bytes(b"name = \"caf\xe9\"\n")
    with pytest.raises(InputError, match=r"not UTF-8 text \(byte 0xe9 at offset 11\)"):
        read_text_file(bad)
    bom = tmp_path / "bom.toml"
    bom.write_bytes(b"\xef\xbb\xbfa = 1\n")
    assert read_text_file(bom) == "a = 1\n"
    big = tmp_path / "big.toml"
    big.write_bytes(b"#" * 100)
    with pytest.raises(InputError, match="larger than 50 bytes"):
        read_text_file(big, max_bytes=50)


@pytest.mark.parametrize("flag, hostile", [("--sensor-config", "deep"), ("--suite", "deep"), ("--config", "fifo")])
def test_the_command_line_refuses_deep_toml_and_fifos(tmp_path, flag, hostile):
    # one process per flag (each path argument goes through the same reader and parser)
    path = tmp_path / "hostile.toml"
    os.mkfifo(path) if hostile == "fifo" else path.write_text(DEEP)
    out = tmp_path / "out"
    done, seconds = _cli(flag, str(path), "--out", str(out), timeout=60)
    _refused(done, "not a regular file" if hostile == "fifo" else "nested more than", out)
    assert seconds < 30


def test_a_coordinator_address_without_a_port_is_one_line(tmp_path):
    done, _ = _cli("--distributed", "--coordinator", "garbage", "--num-processes", "2", "--process-id", "0",
                   "--out", str(tmp_path / "out"))
    _refused(done, "HOST:PORT")


def test_an_error_line_echoing_a_huge_value_fits_on_a_screen(tmp_path):
    done, _ = _cli("--scenarios", "x" * 100_000, "--out", str(tmp_path / "out"))
    _refused(done, "xxx")
    assert len(done.stderr) < 1000


def test_long_options_are_not_matched_by_a_prefix(tmp_path):
    # `--interv` would once have been read as `--interval`
    done, _ = _cli("--param", "hfov", "--interv", "30", "180", "--out", str(tmp_path / "out"))
    _refused(done, "--interv")


# -- outputs and the Python API ----------------------------------------------------------------------

def test_result_files_are_strict_json(tmp_path):
    path = tmp_path / "r.json"
    write_json(path, {"J": float("inf"), "E": [1.5, float("nan"), -float("inf")], "n": {"x": 2}})
    text = path.read_text()

    def refuse(name):
        raise AssertionError(f"{name} in the JSON")

    assert json.loads(text, parse_constant=refuse) == {"J": None, "E": [1.5, None, None], "n": {"x": 2}}


@pytest.fixture(scope="module")
def E():
    problem = ds.Problem(sensor="radar", params={"hfov_deg": (30.0, 180.0)}, scenarios=["sc01"], variants=1,
                         steps=(30.0, 180.0))
    return ds.objective(problem)


@pytest.mark.parametrize("r, needle", [
    ({"hfov_deg": float("nan")}, "outside its domain"),
    ({"hfov_deg": float("inf")}, "outside its domain"),
    ({"hfov_deg": -30.0}, "hfov_deg = -30 is outside its domain (0, 360] deg"),
    ({"hfov_deg": 1000.0}, "outside its domain"),
    ({"range_m": -100.0}, "range_m = -100"),
    ({"hfov_deg": "wide"}, "hfov_deg must be a number"),
    ({"hfov_deg": [30.0, 60.0]}, "must be one number"),
    ({"hfov": 45.0}, "unknown radar parameter 'hfov'"),
    (45.0, "must be a dict"),
])
def test_the_python_api_refuses_what_it_cannot_compute(E, r, needle):
    with pytest.raises(InputError) as refused:
        E(r)
    assert needle in str(refused.value)


def test_traced_values_pass_and_nan_is_never_the_best_value(E):
    # under jit and vmap the values are a solver's: no host check, the same E as eagerly
    eager = float(E({"hfov_deg": 45.0}))
    assert float(jax.jit(E)({"hfov_deg": jnp.asarray(45.0)})) == pytest.approx(eager, rel=1e-6)
    batch = jax.vmap(lambda h: E({"hfov_deg": h}))(jnp.asarray([45.0, 90.0]))
    assert np.all(np.isfinite(np.asarray(batch)))
    # an E^2 that could not be computed stays NaN (not 0, the best value); 0 and below give 0
    assert np.isnan(float(safe_sqrt(jnp.asarray(np.nan)))) and float(safe_sqrt(jnp.asarray(-1e-30))) == 0.0
    assert float(jax.grad(safe_sqrt)(0.0)) == 0.0
