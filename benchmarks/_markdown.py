"""A measured table's block in a Markdown page: the lines between `<!-- NAME -->` and
`<!-- /NAME -->`, replaced by the table a benchmark renders from its results JSON."""

from __future__ import annotations

from pathlib import Path


def replace_block(markdown: Path, name: str, body: str) -> None:
    """Replace the block `name` of `markdown` with `body`; refuses (SystemExit) a page without it."""
    text = markdown.read_text()
    start, end = f"<!-- {name} -->", f"<!-- /{name} -->"
    if start not in text or end not in text:
        raise SystemExit(f"error: {markdown} has no {start} ... {end} block")
    head, rest = text.split(start, 1)
    markdown.write_text(f"{head}{start}\n{body}\n{end}{rest.split(end, 1)[1]}")
