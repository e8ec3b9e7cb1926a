"""A measured table's block in a Markdown page: the lines between `<!-- NAME -->` and
`<!-- /NAME -->`, replaced by the table a benchmark renders from its results JSON."""

from __future__ import annotations

import json
import os
import platform
from collections.abc import Callable, Iterable
from pathlib import Path

import jax


def replace_block(markdown: Path, name: str, body: str) -> None:
    """Replace the block `name` of `markdown` with `body`; refuses (SystemExit) a page without it."""
    text = markdown.read_text()
    start, end = f"<!-- {name} -->", f"<!-- /{name} -->"
    if start not in text or end not in text:
        raise SystemExit(f"error: {markdown} has no {start} ... {end} block")
    head, rest = text.split(start, 1)
    markdown.write_text(f"{head}{start}\n{body}\n{end}{rest.split(end, 1)[1]}")


def measured_rows(path: Path, render_only: bool, rows: Iterable[Callable[[], dict]], keep: bool = False) -> dict:
    """A results JSON {"rows", "meta"}: read from `path` where `render_only`, otherwise measured
    row by row (`rows`, each a function returning one; after the stored rows where `keep`), the
    file rewritten as each row ends so that an interrupted run keeps the rows it finished."""
    if render_only:
        return json.loads(path.read_text())
    res = {"rows": [], "meta": {"machine": platform.platform(), "cpus": os.cpu_count(), "jax": jax.__version__}}
    if keep and path.exists():
        res["rows"] = json.loads(path.read_text())["rows"]
    for row in rows:
        res["rows"].append(row())
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(res, indent=1) + "\n")
    return res
