"""The command line's progress display pinned on a clock set by hand: stage lines, one line per
evaluation with E, cost and ETA (the median time of an evaluation after the first of each
kind), the long-run estimate said once and even under --quiet, and the bar on a terminal."""

from __future__ import annotations

import io
from types import SimpleNamespace

import pytest

from diffsense.cli import _progress
from diffsense.cli._progress import LONG_RUN_S, Progress


class _Clock:
    def __init__(self):
        self.now = 100.0

    def perf_counter(self) -> float:
        return self.now


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


class _Log(io.StringIO):
    """A pipe's view: what was flushed by when."""

    def __init__(self):
        super().__init__()
        self.flushed: list[str] = []

    def flush(self) -> None:
        self.flushed.append(self.getvalue())


@pytest.fixture
def clock(monkeypatch):
    c = _Clock()
    monkeypatch.setattr(_progress, "time", SimpleNamespace(perf_counter=c.perf_counter))
    return c


def _event(kind: str, done: int, planned: int, e_m: float = 1.234567, **extra):
    return {"kind": kind, "done": done, "planned": planned, "E_m": e_m, **extra}


def _at(clock: _Clock, progress: Progress, t: float, event: dict) -> None:
    clock.now = 100.0 + t
    progress.evaluation(event)


def test_stage_lines_say_the_time_since_the_start(clock):
    out = io.StringIO()
    progress = Progress(quiet=False, stream=out)
    clock.now = 102.3
    progress("simulating scenes")
    clock.now = 1334.56
    progress("solving")
    assert out.getvalue() == "[   2.3 s] simulating scenes\n[1234.6 s] solving\n"


def test_one_line_per_evaluation_with_the_median_after_each_kinds_first(clock):
    out = io.StringIO()
    progress = Progress(quiet=False, stream=out)
    _at(clock, progress, 1.0, _event("soft", 1, 10))  # first soft: compiling, not timed
    _at(clock, progress, 3.0, _event("soft", 2, 10))  # 2 s: 8 left x 2 s
    _at(clock, progress, 4.0, _event("hard", 3, 10, 2.0))  # first hard: not timed
    _at(clock, progress, 5.0, _event("hard", 4, 10, 2.0, cost=12.5))  # median(2, 1) x 6
    _at(clock, progress, 9.0, _event("soft", 12, 11))  # more done than planned: planned grows
    assert out.getvalue().splitlines() == [
        "[   1.0 s] evaluation 1/10: E soft = 1.2346 m",
        "[   3.0 s] evaluation 2/10: E soft = 1.2346 m, ETA 16 s",
        "[   4.0 s] evaluation 3/10: E hard = 2.0000 m, ETA 14 s",
        "[   5.0 s] evaluation 4/10: E hard = 2.0000 m, cost 12.50, ETA 9 s",
        "[   9.0 s] evaluation 12/12: E soft = 1.2346 m, ETA 0 s",
    ]


def test_a_long_run_is_announced_once_even_when_quiet(clock):
    out = io.StringIO()
    progress = Progress(quiet=True, stream=out)
    _at(clock, progress, 0.0, _event("soft", 1, 12))
    _at(clock, progress, 6.0, _event("soft", 2, 12))  # 10 left x 6 s = 60 s: not more than a minute
    assert out.getvalue() == "" and LONG_RUN_S == 60.0
    _at(clock, progress, 18.0, _event("soft", 3, 12))  # median(6, 12) = 9 s x 9 left = 81 s
    _at(clock, progress, 40.0, _event("soft", 4, 12))
    assert out.getvalue() == "[  18.0 s] estimate: 9 evaluations left x 9.0 s = about 1.4 min\n"
    progress("a stage")
    assert out.getvalue().count("\n") == 1


def test_the_estimate_comes_before_the_evaluations_line(clock):
    out = io.StringIO()
    progress = Progress(quiet=False, stream=out)
    _at(clock, progress, 0.0, _event("soft", 1, 100))
    _at(clock, progress, 2.0, _event("soft", 2, 100))
    assert out.getvalue().splitlines()[1:] == [
        "[   2.0 s] estimate: 98 evaluations left x 2.0 s = about 3.3 min",
        "[   2.0 s] evaluation 2/100: E soft = 1.2346 m, ETA 196 s"]


def test_a_terminal_gets_one_bar_closed_by_the_next_stage(clock):
    out = _Terminal()
    progress = Progress(quiet=False, stream=out)
    _at(clock, progress, 1.0, _event("soft", 3, 10))
    bar = progress._bar
    assert bar is not None and bar.total == 10 and bar.n == 3  # starts at the events already done
    assert "2/10 [" in out.getvalue() and "eval/s]" in out.getvalue()  # its first drawing, here
    _at(clock, progress, 2.0, _event("soft", 4, 12, cost=3.0))
    assert progress._bar is bar and bar.total == 12 and bar.n == 4
    assert "E soft = 1.2346 m, cost 3.00, ETA 8 s" in bar.postfix
    assert "evaluation 4/12" not in out.getvalue()  # no plain lines on a terminal
    clock.now = 103.0
    progress("done")
    assert progress._bar is None and bar.disable  # closed
    assert out.getvalue().endswith("[   3.0 s] done\n")


def test_quiet_prints_neither_stages_nor_evaluations(clock):
    out = _Terminal()
    progress = Progress(quiet=True, stream=out)
    progress("stage")
    _at(clock, progress, 1.0, _event("soft", 1, 3))
    _at(clock, progress, 2.0, _event("soft", 2, 3))
    assert out.getvalue() == "" and progress._bar is None


def test_every_line_is_flushed_as_it_is_written(clock):
    out = _Log()
    progress = Progress(quiet=False, stream=out)
    progress("stage")
    _at(clock, progress, 1.0, _event("soft", 1, 100))
    _at(clock, progress, 3.0, _event("soft", 2, 100))  # the estimate, then the line
    lines = out.getvalue().splitlines(keepends=True)
    assert out.flushed == ["".join(lines[:n]) for n in range(1, 5)]


def test_the_bar_draws_once_per_evaluation(clock, monkeypatch):
    from tqdm import tqdm

    refreshes = []
    original = tqdm.set_postfix_str
    monkeypatch.setattr(tqdm, "set_postfix_str", lambda self, s="", refresh=True: (refreshes.append(refresh),
                                                                                   original(self, s, refresh)))
    progress = Progress(quiet=False, stream=_Terminal())
    _at(clock, progress, 1.0, _event("soft", 1, 10))
    _at(clock, progress, 2.0, _event("soft", 2, 10))
    assert refreshes == [False, False]  # the update that follows draws it
