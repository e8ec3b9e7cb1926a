"""Copy the documentation's figures out of the executed notebooks' committed outputs.

    python docs/extract_figures.py

The figures in docs/img/ are the PNG outputs of notebooks/0N_*.ipynb as committed (made by
`python notebooks/execute.py 0N`), byte for byte: the docs never show a figure that no command in
the repository drew. Each entry names the cell by the start of its source, so that a figure moves
with its cell when cells are added; run this again after re-executing a notebook.
"""

from __future__ import annotations

import base64
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# docs/img/<name>: (notebook, start of the cell's source, index of the PNG among its outputs)
FIGURES = {
    "e_over_hfov.png": ("01_gradient_sensitivity", "HFOV = {}", 0),
    "baseline_hfov_30_180.png": ("03_grid_search_baseline", "curves_hfov, ref_hfov", 0),
    "baseline_hfov_5_60.png": ("03_grid_search_baseline", "curves_narrow, ref_narrow", 0),
    "odd_camera.png": ("06_odd_sensitivity", "draw(CAMERA", 0),
    "odd_radar.png": ("06_odd_sensitivity", "RADAR_RESULTS = {}", 0),
}


def cell_pngs(notebook: str, source_start: str) -> list[bytes]:
    """The PNG outputs of the one code cell whose source starts with `source_start`."""
    nb = json.loads((ROOT / "notebooks" / f"{notebook}.ipynb").read_text())
    cells = [c for c in nb["cells"] if c["cell_type"] == "code" and "".join(c["source"]).startswith(source_start)]
    if len(cells) != 1:
        raise SystemExit(f"error: {len(cells)} cells of {notebook} start with {source_start!r}, expected 1")
    outs = [o["data"]["image/png"] for o in cells[0].get("outputs", []) if "image/png" in o.get("data", {})]
    return [base64.b64decode(png if isinstance(png, str) else "".join(png)) for png in outs]


def main() -> None:
    out = ROOT / "docs" / "img"
    out.mkdir(exist_ok=True)
    for name, (notebook, start, index) in FIGURES.items():
        pngs = cell_pngs(notebook, start)
        if index >= len(pngs):
            raise SystemExit(f"error: {notebook} cell {start!r} has {len(pngs)} figures, wanted #{index}")
        (out / name).write_bytes(pngs[index])
        print(f"docs/img/{name}  <- notebooks/{notebook}.ipynb, cell {start!r}, figure {index}")


if __name__ == "__main__":
    main()
