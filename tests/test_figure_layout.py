"""The run's figures keep every label inside the figure and apart: the margins are fixed in
inches, so a panel's tick labels, axis labels and title, the legend and the figure title must
not overlap one another or leave the canvas, for one to six scenario panels."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.transforms import Bbox

from diffsense.report import _figures

TITLE = "radar: hfov_deg [deg] over [30, 180], six scenarios, 8 variants each"


def _boxes(fig):
    """Window extents [px] of each panel (with its labels, title and twin axis), the legend and
    the figure title."""
    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    panels = {}  # a twin axis sits where its panel sits: one box for both
    for ax in fig.axes:
        if ax.get_visible():
            panels.setdefault(tuple(ax.get_position().bounds), []).append(ax.get_tightbbox(renderer))
    boxes = {f"panel {i}": Bbox.union(parts) for i, parts in enumerate(panels.values())}
    boxes.update({f"legend {i}": lg.get_window_extent(renderer) for i, lg in enumerate(fig.legends)})
    if fig._suptitle is not None:
        boxes["title"] = fig._suptitle.get_window_extent(renderer)
    return boxes, fig.bbox


def _drawn(monkeypatch, plot, *args, **kwargs):
    """The figure `plot` saves, caught on its way to the file."""
    figures = []
    monkeypatch.setattr(_figures, "save_figure", lambda fig, path, **_: figures.append(fig))
    plot("unused.png", *args, **kwargs)
    (fig,) = figures
    return fig


def _assert_apart_and_inside(fig):
    boxes, canvas = _boxes(fig)
    for name, box in boxes.items():
        assert canvas.x0 <= box.x0 and box.x1 <= canvas.x1 and canvas.y0 <= box.y0 and box.y1 <= canvas.y1, name
    for (a, box_a), (b, box_b) in itertools.combinations(boxes.items(), 2):
        assert not box_a.overlaps(box_b), f"{a} overlaps {b}"


@pytest.mark.parametrize("n_scenarios", [1, 2, 3, 6])
def test_horizon_panels_labels_and_legend_stay_apart_and_inside(monkeypatch, n_scenarios):
    rng = np.random.default_rng(0)
    gt = np.linspace(0.1, 180.0, 25)  # three-digit tick labels
    curves = {f"sc0{i}": {"gt": gt, "steps": {np.deg2rad(r): gt * rng.uniform(1.0, 2.0) for r in range(30, 181, 30)}}
              for i in range(1, n_scenarios + 1)}
    fig = _drawn(monkeypatch, _figures.plot_rmse_horizon, curves, param="hfov", scale=180 / np.pi, unit="deg",
                 title=TITLE)
    _assert_apart_and_inside(fig)


@pytest.mark.parametrize("title", ["", TITLE])
def test_objective_axes_twin_axis_and_legend_stay_apart_and_inside(monkeypatch, title):
    r = np.deg2rad(np.linspace(30.0, 180.0, 41))
    e_soft = 50.0 + 40.0 * (r - r[0])
    sweep = [{"r": x, "E_hard": 50.0 + 40.0 * (x - r[0])} for x in r[::8]]
    fig = _drawn(monkeypatch, _figures.plot_objective, r, e_soft, e_soft + 0.3, np.gradient(e_soft, r) * 1e-4, sweep,
                 float(r[0]), param="hfov", scale=180 / np.pi, unit="deg", title=title)
    _assert_apart_and_inside(fig)
