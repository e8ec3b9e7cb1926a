"""Every notebook runs top to bottom headless in fast mode (DIFFSENSE_NOTEBOOK_FAST=1) without
an error; the committed copies carry outputs, figures and no error output."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"
sys.path.insert(0, str(NOTEBOOKS))
import execute  # noqa: E402

PATHS = execute.notebooks([])


def test_the_four_notebooks_exist():
    names = [p.name[:2] for p in PATHS]
    assert names == ["01", "02", "03", "04"], names


@pytest.mark.parametrize("path", PATHS, ids=[p.stem for p in PATHS])
def test_committed_notebook_is_executed_with_figures_and_no_error(path):
    nb = json.loads(path.read_text())
    code = [c for c in nb["cells"] if c["cell_type"] == "code"]
    assert code and all(c.get("execution_count") for c in code), "not executed top to bottom"
    outputs = [o for c in code for o in c.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"], "an error output"
    assert any("image/png" in o.get("data", {}) for o in outputs), "no figure"
    assert path.stat().st_size < 2_000_000


@pytest.mark.parametrize("path", PATHS, ids=[p.stem for p in PATHS])
def test_notebook_runs_in_fast_mode(path, tmp_path, monkeypatch):
    # A private compilation cache shared by the notebooks of this session (same fast shapes).
    monkeypatch.setenv("XDG_CACHE_HOME", str(NOTEBOOKS.parent / ".pytest_cache" / "notebook-xla"))
    monkeypatch.setenv("MPLBACKEND", "Agg")
    execute.execute(path, fast=True, timeout_s=600, write=False)
