"""The command line's --pareto run pinned in-process on a front built by hand: what it asks of
`diffsense.pareto`, the files it publishes as one set, its progress line and printed table, and
nothing published when the sweep fails."""

from __future__ import annotations

import dataclasses
import json

import pytest

import diffsense as ds
from diffsense import report
from diffsense.cli._suite import pareto_run
from tests.test_suite_solve_pinned import _front as _hand_front


def _front():
    return dataclasses.replace(_hand_front(), units={"hfov_deg": "deg", "range_m": "m"})


def test_a_pareto_run_publishes_the_front_and_prints_its_table(tmp_path, monkeypatch, capsys):
    asked = []

    def pareto(problem, lambdas, **kw):
        asked.append((problem, lambdas, kw))
        return _front()

    lines = []
    monkeypatch.setattr(ds, "pareto", pareto)
    out = tmp_path / "out"
    assert pareto_run("the problem", (0.0, 0.01), out, "the predictor", _Progress(lines)) == 0
    (problem, lambdas, kw), = asked
    assert (problem, lambdas) == ("the problem", (0.0, 0.01))
    assert kw["predictor"] == "the predictor" and kw["on_evaluation"] == "hook"  # the display's own hook
    assert isinstance(kw["progress"], _Progress)
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json", "pareto.json", "pareto.png"]
    content = json.loads((out / "pareto.json").read_text())
    assert content == json.loads(json.dumps(_front().to_dict()))
    assert lines == [f"wrote {out}/: pareto.json, pareto.png"]
    assert capsys.readouterr().out == "\n" + report.pareto_table(content) + "\n"


class _Progress:
    def __init__(self, lines):
        self.lines, self.evaluation = lines, "hook"

    def __call__(self, message):
        self.lines.append(message)


def test_a_failed_sweep_publishes_nothing(tmp_path, monkeypatch):
    def pareto(problem, lambdas, **kw):
        raise ds.InputError("no front")

    monkeypatch.setattr(ds, "pareto", pareto)
    out = tmp_path / "out"
    with pytest.raises(ds.InputError, match="^no front$"):
        pareto_run("p", (0.0, 0.01), out, None, _Progress([]))
    assert not out.exists() or not [p for p in out.iterdir() if not p.name.startswith(".")]
