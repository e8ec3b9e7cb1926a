"""report.html (`diffsense.report.html_report`): from a stored result.json, a page that parses,
reaches nothing outside itself, and shows the answer's numbers as result.json holds them."""

from __future__ import annotations

import json
import re
from html.parser import HTMLParser
from pathlib import Path

import pytest

from diffsense.report import html_report

GOLDEN = Path(__file__).resolve().parent / "golden"


def _values(page: str) -> dict[str, str]:
    return dict(re.findall(r'data-key="([^"]+)" data-value="([^"]+)"', page))


@pytest.mark.parametrize("name", ["line_result.json", "box_result.json"])
def test_the_page_shows_result_json_s_answer_and_reaches_nothing_outside(name):
    content = json.loads((GOLDEN / name).read_text())
    page = html_report(content, {"objective.png": b"\x89PNG fake"})
    HTMLParser().feed(page)
    assert not re.search(r"https?:|//cdn|<script|<link", page)
    values = _values(page)
    ref = content["reference"] or {}
    e = ref["E_ref_star"] if ref.get("answer_on") == "E_ref" else content["E_hard_star"]
    assert float(values["E"]) == e
    for n, v in content["r_star"].items():
        assert float(values[f"r_star.{n}"]) == v
    if content["E_ci"]:
        assert [float(values["E_ci.lo"]), float(values["E_ci.hi"])] == content["E_ci"]
    for n, (lo, hi) in (content["r_star_ci"] or {}).items():
        assert [float(values[f"r_star_ci.{n}.lo"]), float(values[f"r_star_ci.{n}.hi"])] == [lo, hi]
    for c in content["comparisons"]:
        assert c["verdict"] in page or __import__("html").escape(c["verdict"]) in page
