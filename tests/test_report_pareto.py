"""The Pareto sweep's outputs from a front written by hand (pareto.json's content): the printed
table's numbers, which E it is judged on, and what pareto.png draws (the evaluated cloud, the
front joined cheapest first, the dominated designs hollow, one label per design); pareto.json
written as the front's content."""

from __future__ import annotations

import json

import numpy as np
import pytest
from matplotlib.figure import Figure
from test_report_tables import numbers

from diffsense.report import PARETO_FILES, pareto_table, plot_pareto, write_pareto

DESIGNS = ((0.0, 4.0, 3.0, True), (0.01, 6.0, 1.0, True), (0.02, 7.0, 2.0, False), (0.05, 9.0, 0.5, True))


def _content(judged_on: str = "E_hard") -> dict:
    key = f"{judged_on}_m"
    return {"sensor": "radar+camera", "judged_on": judged_on, "currency": "EUR",
            "units": {"hfov_deg": "deg", "range_m": "m"}, "lambdas": [d[0] for d in DESIGNS], "front": [3, 1, 0],
            "evaluations": {"soft": 20, "hard": 9}, "wall_s": 12.5, "cloud": {"cost": [1.0, 3.0], key: [6.0, 4.0]},
            "designs": [{"lambda": lam, "r_star": {"hfov_deg": 30.0, "range_m": 70.0 + k}, key: e, "cost": c,
                         "on_front": on} for k, (lam, e, c, on) in enumerate(DESIGNS)]}


class _Front:
    """A `diffsense.ParetoFront` as far as `write_pareto` reads it."""
    sensor, judged_on, currency = "radar+camera", "E_hard", "EUR"

    def to_dict(self) -> dict:
        return _content()


@pytest.fixture
def drawn(monkeypatch):
    figures = []
    monkeypatch.setattr(Figure, "savefig", lambda fig, file, **kw: figures.append(fig))
    return figures


def test_the_table_holds_each_design_s_numbers():
    text = pareto_table(_content())
    lines = text.splitlines()
    assert numbers(text) == [[4, 20, 9], [], [], [0, 4.0, 3.0, 30.0, 70.0], [0.01, 6.0, 1.0, 30.0, 71.0],
                             [0.02, 7.0, 2.0, 30.0, 72.0], [0.05, 9.0, 0.5, 30.0, 73.0]]
    assert [line.split()[3] for line in lines[3:]] == ["yes", "yes", "no", "yes"]  # on the front
    assert "E_hard" in lines[1] and "EUR" in lines[1] and "deg" in lines[1]
    ref = _content("E_ref")
    assert "E_ref" in pareto_table(ref).splitlines()[1] and numbers(pareto_table(ref))[3][1] == 4.0
    old = _content()
    del old["judged_on"]  # pareto.json written before `judged_on` existed: E_hard
    assert pareto_table(old) == text
    assert numbers(pareto_table(dict(_content(), designs=[])))[1:] == [[], []]


def test_the_figure_draws_the_cloud_the_front_and_the_dominated_designs(drawn, tmp_path):
    labels = plot_pareto(tmp_path / "p.png", _content(), "the title")
    (fig,) = drawn
    assert labels == ["lambda = 0", "lambda = 0.01", "lambda = 0.02", "lambda = 0.05"]
    (ax,) = fig.axes
    cloud, dominated = ax.collections
    np.testing.assert_array_equal(cloud.get_offsets(), [[1.0, 6.0], [3.0, 4.0]])
    np.testing.assert_array_equal(dominated.get_offsets(), [[2.0, 7.0]])
    assert dominated.get_facecolors().size == 0  # hollow
    (line,) = ax.lines
    np.testing.assert_array_equal(line.get_xydata(), [[0.5, 9.0], [1.0, 6.0], [3.0, 4.0]])  # cheapest first
    assert [(t.get_text(), t.xy) for t in ax.texts] == [(label, (c, e)) for label, (_, e, c, _) in zip(labels, DESIGNS)]
    assert (ax.get_xlabel(), ax.get_ylabel(), ax.get_title()) == ("cost [EUR]", "E_hard [m]", "the title")
    every = _content()
    for d in every["designs"]:
        d["on_front"] = True
    plot_pareto(tmp_path / "p.png", every, "t")
    assert len(drawn[1].axes[0].collections) == 1  # no hollow points
    plot_pareto(tmp_path / "p.png", _content("E_ref"), "t")
    assert drawn[2].axes[0].get_ylabel() == "E_ref [m]"


def test_write_pareto_writes_the_front_s_json_and_its_figure(tmp_path):
    content = write_pareto(_Front(), tmp_path)
    assert content == _content() and json.loads((tmp_path / "pareto.json").read_text()) == content
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(PARETO_FILES)
    assert (tmp_path / "pareto.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
