"""Reading a committed notebook's stored outputs and prose, for the tests of its claims."""

from __future__ import annotations

import json
import re
from pathlib import Path

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"
NUMBER = r"[-+]?\d+(?:\.\d+)?"


def cells(stem: str) -> list[dict]:
    return json.loads((NOTEBOOKS / f"{stem}.ipynb").read_text())["cells"]


def printed(stem: str, marker: str) -> str:
    """The printed text of the first code cell whose output contains `marker`."""
    for cell in cells(stem):
        text = "".join("".join(o.get("text", "")) for o in cell.get("outputs", []))
        if marker in text:
            return text
    raise AssertionError(f"no output of {stem} contains {marker!r}")


def prose(stem: str, heading: str) -> str:
    """The markdown cell that starts with `heading`, on one line."""
    for cell in cells(stem):
        text = "".join(cell["source"])
        if cell["cell_type"] == "markdown" and text.startswith(heading):
            return " ".join(text.split())
    raise AssertionError(f"no markdown cell of {stem} starts with {heading!r}")


def table(text: str, header: str, rows: int) -> list[tuple[str, list[float]]]:
    """The `rows` lines after the line holding `header` (rules of dashes skipped): each line's
    label (its text before the first number that starts a word) and every number from there."""
    lines = text[text.index(header):].splitlines()[1:]
    lines = [ln for ln in lines if not set(ln.replace(" ", "")) <= set("-|")][:rows]
    out = []
    for ln in lines:
        first = re.search(rf"(?<![\w.]){NUMBER}", ln)
        out.append((ln[: first.start()].strip(" |"), [float(x) for x in re.findall(NUMBER, ln[first.start():])]))
    return out


def says(prose: str, *phrases: str) -> None:
    for phrase in phrases:
        assert phrase in prose, f"the conclusions no longer say {phrase!r}"
