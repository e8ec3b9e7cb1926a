"""The Pareto sweep's outputs pinned on a front built by hand: the printed table whole, and what
pareto.png draws (the evaluated cloud, the front joined in its order, the dominated designs
hollow, one label per design at alternating offsets, axes, title and legend)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from matplotlib.colors import to_hex

from diffsense.report import _pareto
from diffsense.report._pareto import pareto_table, plot_pareto, write_pareto
from tests.test_cli_pareto_pinned import _front


def test_the_table_whole():
    content = _front().to_dict()
    assert pareto_table(content) == (
        "radar+camera: E-versus-cost front, 4 cost weights [m per EUR]; 20 value-and-gradient + 9 hard evaluations\n"
        "lambda  E_hard [m]  cost [EUR]  front  hfov_deg [deg]  range_m [m]\n"
        "------  ----------  ----------  -----  --------------  -----------\n"
        "0           4.0000      3.0000    yes         30.0000      70.0000\n"
        "0.01        6.0000      1.0000    yes         30.0000      70.0000\n"
        "0.02        7.0000      2.0000     no         30.0000      70.0000\n"
        "0.05        9.0000      0.5000    yes         30.0000      70.0000")
    content["judged_on"] = "E_ref"
    for d, value in zip(content["designs"], (4.5, 6.5, 7.5, 9.5)):
        d["E_ref_m"] = value
    assert pareto_table(content).splitlines()[1].startswith("lambda  E_ref [m]  cost [EUR]")
    assert pareto_table(content).splitlines()[3].split()[:2] == ["0", "4.5000"]
    empty = dict(content, designs=[])
    assert pareto_table(empty).splitlines()[1:] == ["lambda  E_ref [m]  cost [EUR]  front", "------  ---------  ----------  -----"]


@pytest.fixture
def drawn(monkeypatch):
    figures = []
    monkeypatch.setattr(_pareto, "save_figure", lambda fig, path, dpi: figures.append((fig, path, dpi)))
    return figures


def test_what_the_figure_draws(drawn, tmp_path):
    content = _front().to_dict()
    labels = plot_pareto(tmp_path / "p.png", content, "the title")
    assert labels == ["lambda = 0", "lambda = 0.01", "lambda = 0.02", "lambda = 0.05"]
    (fig, path, dpi), = drawn
    assert path == tmp_path / "p.png" and dpi == 120
    ax, = fig.axes
    cloud, dominated = ax.collections
    np.testing.assert_array_equal(cloud.get_offsets(), [[1.0, 6.0], [3.0, 4.0]])
    np.testing.assert_array_equal(dominated.get_offsets(), [[2.0, 7.0]])
    assert dominated.get_facecolors().size == 0  # hollow
    line, = ax.lines
    np.testing.assert_array_equal(line.get_xydata(), [[0.5, 9.0], [1.0, 6.0], [3.0, 4.0]])  # the front, cheapest first
    texts = [(t.get_text(), t.xy, t.xyann) for t in ax.texts]
    assert texts == [("lambda = 0", (3.0, 4.0), (6, 6)), ("lambda = 0.01", (1.0, 6.0), (6, -12)),
                     ("lambda = 0.02", (2.0, 7.0), (6, 6)), ("lambda = 0.05", (0.5, 9.0), (6, -12))]
    assert all(t.anncoords == "offset points" for t in ax.texts)
    assert (ax.get_xlabel(), ax.get_ylabel(), ax.get_title()) == ("cost [EUR]", "E_hard [m]", "the title")
    # The cloud grey behind; the front joined, with markers; the dominated designs hollow, edged in red.
    assert to_hex(cloud.get_facecolors()[0]) == "#bfbfbf" and cloud.get_zorder() == 1
    assert (line.get_linestyle(), line.get_marker(), line.get_color(), line.get_zorder()) == ("-", "o", "C0", 3)
    assert to_hex(dominated.get_edgecolors()[0]) == to_hex("C3") and dominated.get_zorder() == 3
    assert [t.get_text() for t in ax.get_legend().get_texts()] == [
        "evaluated (hard)", "front (non-dominated designs)", "dominated design"]


def test_a_front_without_judged_on_is_judged_on_e_hard(drawn, tmp_path):
    """pareto.json written before `judged_on` existed."""
    content = _front().to_dict()
    del content["judged_on"]
    assert pareto_table(content).splitlines()[1].startswith("lambda  E_hard [m]  cost [EUR]")
    plot_pareto(tmp_path / "p.png", content, "t")
    assert drawn[0][0].axes[0].get_ylabel() == "E_hard [m]"


def test_every_design_on_the_front_draws_no_hollow_points(drawn, tmp_path):
    content = _front().to_dict()
    for d in content["designs"]:
        d["on_front"] = True
    plot_pareto(tmp_path / "p.png", content, "t")
    ax, = drawn[0][0].axes
    assert len(ax.collections) == 1
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["evaluated (hard)", "front (non-dominated designs)"]


def test_written_as_json_and_png_with_the_fronts_title(drawn, tmp_path):
    content = write_pareto(_front(), tmp_path)
    assert json.loads((tmp_path / "pareto.json").read_text()) == json.loads(json.dumps(_front().to_dict())) == content
    (fig, path, _), = drawn
    assert path == tmp_path / "pareto.png"
    assert fig.axes[0].get_title() == "radar+camera: E_hard against cost, one design per lambda [m per EUR]"
