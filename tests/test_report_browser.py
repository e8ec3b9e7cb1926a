"""report.html in a real headless browser (slow; skipped where no Chromium is on PATH): the page a
small real run writes (`diffsense.optimise`, `diffsense.report.write_run`) loads with no console
error and nothing reached outside it, its embedded figures decode, and the DOM the browser builds
shows the answer's numbers (the elements tagged with result.json's keys) equal to result.json's.
The browser is Debian's `chromium` (`apt-get install chromium`), run as
`chromium --headless --dump-dom`, its console read from `--enable-logging=stderr`."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import pytest

import diffsense as ds
from diffsense.report import write_run

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
BROWSERS = ("chromium", "chromium-browser", "google-chrome")
# After the load event, the page's images as the browser decoded them, written into the DOM the
# browser dumps (the report itself has no script; this one is added to a copy of it).
PROBE = ("<script>window.addEventListener('load', () => document.body.setAttribute('data-images', "
         "[...document.images].map(i => i.complete && i.naturalWidth > 0 ? 'ok' : 'broken').join(',')));</script>")


@pytest.fixture(scope="module")
def browser() -> str:
    """The browser's path; skips the module's tests where none is on PATH (before any run)."""
    for name in BROWSERS:
        if path := shutil.which(name):
            return path
    pytest.skip(f"no headless browser on PATH ({', '.join(BROWSERS)})")


def _load(browser: str, page: Path, profile: Path) -> tuple[str, list[str]]:
    """The DOM `browser` builds from `page` and its console's messages (errors, uncaught
    exceptions, failed loads). No network is used: background networking and updates are off
    and the page is a file."""
    run = subprocess.run(
        [browser, "--headless", "--disable-gpu", "--no-sandbox", "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--disable-extensions", f"--user-data-dir={profile}",
         "--enable-logging=stderr", "--v=0", "--virtual-time-budget=5000", "--dump-dom", page.as_uri()],
        capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    console = [line for line in run.stderr.splitlines() if re.search(r"CONSOLE|Uncaught|net::ERR_", line)]
    return run.stdout, console


class _Tagged(HTMLParser):
    """data-key -> data-value of every element the report tagged with a result.json key."""

    def __init__(self):
        super().__init__()
        self.values: dict[str, str] = {}
        self.body: dict[str, str | None] = {}

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if "data-key" in a:
            self.values[a["data-key"]] = a["data-value"]
        if tag == "body":
            self.body = a


@pytest.fixture(scope="module")
def run(browser, tmp_path_factory) -> Path:
    """A small real run's folder: radar HFOV 30-180 over three steps, one scenario, two variants
    (so it has intervals), the threshold law; report.html with its three figures."""
    folder = tmp_path_factory.mktemp("run")
    problem = ds.Problem(sensor="radar", params={"hfov_deg": (30.0, 180.0)}, scenarios=["sc05"], variants=2,
                         steps=(30.0, 105.0, 180.0), sensor_config=str(ROOT / "configs/sensors/laws/radar_threshold.toml"))
    write_run(ds.optimise(problem, judge=False), folder)
    return folder


def test_the_browser_catches_a_console_error(browser, tmp_path):
    """The console is read: a page that logs an error and throws is caught (the check below
    would otherwise pass on a browser that reported nothing)."""
    page = tmp_path / "bad.html"
    page.write_text("<!DOCTYPE html><html><body><script>console.error('boom'); missing();</script></body></html>")
    dom, console = _load(browser, page, tmp_path / "profile")
    assert "<body>" in dom and any("boom" in line for line in console) and any("Uncaught" in line for line in console)


def test_report_html_loads_without_errors_and_shows_result_json_s_numbers(browser, run, tmp_path):
    content = json.loads((run / "result.json").read_text())
    page = tmp_path / "report.html"
    page.write_text((run / "report.html").read_text().replace("</body>", PROBE + "</body>"))
    dom, console = _load(browser, page, tmp_path / "profile")
    assert console == []
    tagged = _Tagged()
    tagged.feed(dom)
    assert tagged.body.get("data-images") == "ok,ok,ok"  # objective.png, rmse_horizon.png, detections.png
    values = {k: None if v == "null" else float(v) for k, v in tagged.values.items()}
    assert content["reference"]["answer_on"] == "E_hard"  # the threshold law: the answer is on E_hard
    assert values["E"] == content["E_hard_star"]
    assert values["r_star.hfov_deg"] == content["r_star"]["hfov_deg"]
    assert content["E_ci"] is not None and [values["E_ci.lo"], values["E_ci.hi"]] == content["E_ci"]
    assert len(content["sweep"]) == 3
    for i, p in enumerate(content["sweep"]):
        assert (values[f"sweep.{i}.r"], values[f"sweep.{i}.E"]) == (p["r"], p["E_hard"])
        assert [values[f"sweep.{i}.E_ci.lo"], values[f"sweep.{i}.E_ci.hi"]] == p["E_ci"]
    for i, c in enumerate(content["comparisons"]):
        assert values[f"comparisons.{i}.diff_m"] == c["diff_m"]
        assert c["verdict"] in dom
