"""The command line's progress display on a clock set by hand: the seconds since the start on each
line, one line per evaluation off a terminal with its E, cost and ETA (the median time of an
evaluation after the first of each kind, times the evaluations left), the long-run estimate said
once and even under --quiet, nothing else under --quiet, one bar on a terminal; every line
flushed as it is written."""

from __future__ import annotations

import io
import re
import time

import pytest

from diffsense.cli import Progress

NUMBER = r"-?\d+(?:\.\d+)?"


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.fixture
def clock(monkeypatch):
    now = [100.0]
    monkeypatch.setattr(time, "perf_counter", lambda: now[0])
    return now


def _evaluations(clock, progress, *events):
    """Each (t [s], kind, done, planned, E [m], cost or None) at its time."""
    for t, kind, done, planned, e, cost in events:
        clock[0] = 100.0 + t
        progress.evaluation({"kind": kind, "done": done, "planned": planned, "E_m": e, "cost": cost})


def _numbers(line: str) -> list[float]:
    return [float(x) for x in re.findall(NUMBER, line)]


def test_each_evaluation_is_a_line_with_e_cost_and_the_eta(clock):
    out = io.StringIO()
    progress = Progress(quiet=False, stream=out)
    clock[0] = 102.3
    progress("simulating scenes")
    _evaluations(clock, progress,
                 (3.0, "soft", 1, 10, 1.234567, None),  # the first of a kind compiles: not timed
                 (5.0, "soft", 2, 10, 1.5, None),  # 2 s: 8 left x 2 s
                 (6.0, "hard", 3, 10, 2.0, None),  # the first hard: not timed
                 (7.0, "hard", 4, 10, 2.0, 12.5),  # median(2, 1) = 1.5 s x 6 left
                 (9.0, "soft", 12, 11, 1.0, None))  # more done than planned: planned grows
    lines = out.getvalue().splitlines()
    assert _numbers(lines[0]) == [2.3]
    assert [_numbers(line) for line in lines[1:]] == [
        [3.0, 1, 10, 1.2346], [5.0, 2, 10, 1.5, 16], [6.0, 3, 10, 2.0, 14], [7.0, 4, 10, 2.0, 12.5, 9],
        [9.0, 12, 12, 1.0, 0]]


def test_a_long_run_is_announced_once_even_when_quiet(clock):
    out = io.StringIO()
    progress = Progress(quiet=True, stream=out)
    _evaluations(clock, progress, (0.0, "soft", 1, 12, 1.0, None), (6.0, "soft", 2, 12, 1.0, None))
    assert out.getvalue() == ""  # 10 left x 6 s = 60 s: not more than a minute
    _evaluations(clock, progress, (18.0, "soft", 3, 12, 1.0, None),  # median(6, 12) = 9 s x 9 left = 81 s
                 (40.0, "soft", 4, 12, 1.0, None))
    progress("a stage")
    (line,) = out.getvalue().splitlines()
    assert _numbers(line) == [18.0, 9, 9.0, 1.4]  # at 18 s: 9 left x 9.0 s = 1.4 min


def test_the_estimate_comes_before_its_evaluation_s_line_and_each_line_is_flushed(clock):
    out = io.StringIO()
    flushed = []
    out.flush = lambda: flushed.append(out.getvalue())
    progress = Progress(quiet=False, stream=out)
    _evaluations(clock, progress, (0.0, "soft", 1, 100, 1.0, None), (2.0, "soft", 2, 100, 1.0, None))
    lines = out.getvalue().splitlines(keepends=True)
    assert [_numbers(line) for line in lines[1:]] == [[2.0, 98, 2.0, 3.3], [2.0, 2, 100, 1.0, 196]]
    assert flushed == ["".join(lines[:n]) for n in range(1, 4)]


def test_a_terminal_gets_one_bar_that_the_next_stage_closes(clock):
    out = _Terminal()
    progress = Progress(quiet=False, stream=out)
    _evaluations(clock, progress, (1.0, "soft", 3, 10, 1.0, None), (2.0, "soft", 4, 12, 1.0, 3.0))
    drawn = out.getvalue()
    assert "2/10" in drawn and not re.search(r"^\[", drawn, re.M)  # a bar from the events done, no plain lines
    clock[0] = 103.0
    progress("done")
    assert _numbers(out.getvalue().splitlines()[-1]) == [3.0]
    quiet = _Terminal()
    progress = Progress(quiet=True, stream=quiet)
    progress("stage")
    _evaluations(clock, progress, (1.0, "soft", 1, 3, 1.0, None), (2.0, "soft", 2, 3, 1.0, None))
    assert quiet.getvalue() == ""
