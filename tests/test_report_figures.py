"""What the run's figures draw, caught on their way to the file: every curve's points in display
units (r times the scale, dE/dr divided by it), the axes named with their units, one panel per
scenario (two a row) or per r, the detection bands as tall as the probability; empty or
misshapen input refused; and every label inside the figure, apart from the others, for one to
six panels."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.transforms import Bbox

from diffsense.report import plot_detection_timeline, plot_objective, plot_rmse_horizon

SCALE = 180.0 / math.pi  # the objective's radians shown as degrees
GT = np.linspace(0.1, 2.5, 25)
OBJECTIVE = {"r": [0.5, 1.0, 1.5], "E_soft": [3.0, 2.0, 2.5], "E_hard": [3.1, 2.2, 2.4], "dE_dr": [-2.0, 0.5, 1.0],
             "sweep": [{"r": 0.5, "E_hard": 3.1, "E_soft": 3.0}, {"r": 1.5, "E_hard": 2.4, "E_soft": 2.5}],
             "r_star": 1.0}


@pytest.fixture
def drawn(monkeypatch):
    """Each figure saved, with savefig's keywords, instead of its bytes."""
    figures = []
    monkeypatch.setattr(Figure, "savefig", lambda fig, file, **kw: figures.append(fig))
    return figures


def _xy(line):
    return np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)


def test_the_objective_figure_draws_its_curves_in_display_units(drawn, tmp_path):
    plot_objective(tmp_path / "objective.png", **OBJECTIVE, param="hfov", scale=SCALE, unit="deg", title="radar")
    (fig,) = drawn
    assert (tmp_path / "objective.png").exists()
    ax, twin = fig.axes
    soft, hard, sweep, r_star = ax.get_lines()
    x = np.array([0.5, 1.0, 1.5]) * SCALE
    np.testing.assert_allclose(_xy(soft), [x, [3.0, 2.0, 2.5]])
    np.testing.assert_allclose(_xy(hard), [x, [3.1, 2.2, 2.4]])
    np.testing.assert_allclose(_xy(sweep), [[0.5 * SCALE, 1.5 * SCALE], [3.1, 2.4]])
    np.testing.assert_allclose(r_star.get_xdata(), [SCALE, SCALE])
    slope, zero = twin.get_lines()
    np.testing.assert_allclose(_xy(slope), [x, np.array([-2.0, 0.5, 1.0]) / SCALE])  # [m/deg]
    np.testing.assert_allclose(zero.get_ydata(), [0.0, 0.0])
    assert (ax.get_xlabel(), ax.get_ylabel(), twin.get_ylabel()) == ("hfov [deg]", "E_RMSE [m]", "dE/dhfov [m/deg]")
    assert "57.2958 deg" in fig.legends[0].get_texts()[3].get_text()  # r* in display units
    assert fig.get_suptitle() == "radar"


def test_the_defaults_name_r_in_its_own_units(drawn, tmp_path):
    plot_objective(tmp_path / "o.png", **OBJECTIVE)
    plot_rmse_horizon(tmp_path / "h.png", {"RLC": {"gt": GT, "steps": {0.5: GT}}})
    plot_detection_timeline(tmp_path / "d.png", {0.5: np.ones((3, 1))}, ["target"])
    objective, horizon, timeline = drawn
    ax, twin = objective.axes
    assert (ax.get_xlabel(), twin.get_ylabel()) == ("r", "dE/dr")
    np.testing.assert_allclose(ax.get_lines()[0].get_xdata(), [0.5, 1.0, 1.5])
    assert [f.get_suptitle() for f in drawn] == [""] * 3
    assert horizon.axes[0].get_lines()[1].get_label() == "r 0.5" and timeline.axes[0].get_title() == "r 0.5"


def test_the_horizon_figure_draws_one_panel_a_scenario_two_a_row(drawn, tmp_path):
    curves = {f"scenario {i}": {"gt": GT + i, "steps": {0.5: 2 * GT + i, "paper": 3 * GT + i}} for i in range(3)}
    plot_rmse_horizon(tmp_path / "h.png", curves, param="hfov", scale=SCALE, unit="deg")
    (fig,) = drawn
    assert [ax.get_visible() for ax in fig.axes] == [True, True, True, False]
    assert fig.axes[0].get_subplotspec().get_gridspec().get_geometry() == (2, 2)
    t = 0.2 * np.arange(1, 26)  # the horizon, 0.2 .. 5 s
    for i, ax in enumerate(fig.axes[:3]):
        gt, step, paper = ax.get_lines()
        for line, want in ((gt, GT + i), (step, 2 * GT + i), (paper, 3 * GT + i)):
            np.testing.assert_allclose(_xy(line), [t, want])
        assert [line.get_label() for line in (step, paper)] == ["hfov 28.6479 deg", "hfov paper"]
        assert (ax.get_title(), ax.get_xlabel(), ax.get_ylabel()) == (f"scenario {i}", "prediction horizon [s]", "RMSE [m]")
    labels = {np.int64(2): GT, np.float32(0.5): GT, 3: GT}  # numpy's numbers scale like Python's
    plot_rmse_horizon(tmp_path / "h.png", {"RLC": {"gt": GT, "steps": labels}}, param="hfov", scale=10.0, unit="deg")
    assert [line.get_label() for line in drawn[1].axes[0].get_lines()][1:] == ["hfov 20 deg", "hfov 5 deg", "hfov 30 deg"]
    assert len(drawn[1].axes) == 1


def test_the_detection_timeline_draws_bands_as_tall_as_the_probability(drawn, tmp_path):
    roles = ["target", "lead", "follower"]
    p = {0.5: np.array([[0.0, 0.5, 1.0], [0.25, 1.5, -0.5], [1.0, 0.5, 0.0], [0.5, 0.5, 0.5]]), "paper": np.full((4, 3), 0.5)}
    plot_detection_timeline(tmp_path / "d.png", p, roles, dt_s=0.2, param="hfov", scale=SCALE, unit="deg")
    (fig,) = drawn
    top, bottom = fig.axes
    assert [ax.get_title() for ax in (top, bottom)] == ["hfov 28.6479 deg", "hfov paper"]
    for v, band in enumerate(top.collections):
        vertices = np.concatenate([path.vertices for path in band.get_paths()])
        assert vertices[:, 1].min() == pytest.approx(v)
        assert vertices[:, 1].max() == pytest.approx(v + 0.8 * np.clip(p[0.5][:, v], 0.0, 1.0).max())
        assert (vertices[:, 0].min(), vertices[:, 0].max()) == pytest.approx((0.0, 0.6))  # 4 frames 0.2 s apart
    assert {float(y) for y in bottom.collections[2].get_paths()[0].vertices[:, 1]} == {2.0, 2.4}
    # Steps held half a frame either side of each frame's time, not lines between frames.
    x_steps = np.unique(np.round(np.concatenate([p.vertices[:, 0] for p in top.collections[0].get_paths()]), 9))
    np.testing.assert_allclose(x_steps, [0.0, 0.1, 0.3, 0.5, 0.6])
    assert [t.get_text() for t in top.get_yticklabels()] == roles
    assert top.get_shared_x_axes().joined(top, bottom) and "time [s]" in bottom.get_xlabel()


@pytest.mark.parametrize("call, culprit", [
    (lambda path: plot_rmse_horizon(path, {}), "scenarios"),
    (lambda path: plot_detection_timeline(path, {}, ["target"]), "timelines"),
    (lambda path: plot_detection_timeline(path, {30.0: np.zeros((5, 3))}, ["target", "lead"]), "(5, 3)"),
    (lambda path: plot_detection_timeline(path, {"a": np.zeros(5)}, ["target"]), "(5,)"),
])
def test_empty_or_misshapen_input_is_refused_and_nothing_written(drawn, tmp_path, call, culprit):
    with pytest.raises(ValueError) as e:
        call(tmp_path / "f.png")
    assert culprit in str(e.value) and drawn == [] and list(tmp_path.iterdir()) == []


def _assert_apart_and_inside(fig):
    """Each panel (with its labels, title and twin axis), legend and the figure title inside the
    canvas and overlapping no other."""
    renderer = FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    panels = {}  # a twin axis sits where its panel sits: one box for both
    for ax in fig.axes:
        if ax.get_visible():
            panels.setdefault(tuple(ax.get_position().bounds), []).append(ax.get_tightbbox(renderer))
    boxes = {f"panel {i}": Bbox.union(parts) for i, parts in enumerate(panels.values())}
    boxes.update({f"legend {i}": lg.get_window_extent(renderer) for i, lg in enumerate(fig.legends)})
    if fig.get_suptitle():
        boxes["title"] = fig._suptitle.get_window_extent(renderer)
    canvas = fig.bbox
    for name, box in boxes.items():
        assert canvas.x0 <= box.x0 and box.x1 <= canvas.x1 and canvas.y0 <= box.y0 and box.y1 <= canvas.y1, name
    for (a, box_a), (b, box_b) in itertools.combinations(boxes.items(), 2):
        assert not box_a.overlaps(box_b), f"{a} overlaps {b}"


TITLE = "radar: hfov_deg [deg] over [30, 180], six scenarios, 8 variants each"


@pytest.mark.parametrize("n_scenarios", [1, 2, 3, 6])
def test_horizon_panels_labels_and_legend_stay_apart_and_inside(drawn, tmp_path, n_scenarios):
    rng = np.random.default_rng(0)
    gt = np.linspace(0.1, 180.0, 25)  # three-digit tick labels
    curves = {f"sc0{i}": {"gt": gt, "steps": {np.deg2rad(r): gt * rng.uniform(1.0, 2.0) for r in range(30, 181, 30)}}
              for i in range(1, n_scenarios + 1)}
    plot_rmse_horizon(tmp_path / "h.png", curves, param="hfov", scale=SCALE, unit="deg", title=TITLE)
    _assert_apart_and_inside(drawn[0])


@pytest.mark.parametrize("title, intervals", [("", False), (TITLE, False), (TITLE, True)])
def test_objective_axes_twin_axis_and_legend_stay_apart_and_inside(drawn, tmp_path, title, intervals):
    r = np.deg2rad(np.linspace(30.0, 180.0, 41))
    e_soft = 50.0 + 40.0 * (r - r[0])
    sweep = [{"r": x, "E_hard": 50.0 + 40.0 * (x - r[0])} for x in r[::8]]
    ci = {}
    if intervals:  # the legend's three interval rows too
        sweep = [p | {"E_ci": [p["E_hard"] - 2.0, p["E_hard"] + 3.0]} for p in sweep]
        ci = {"E_star": 50.1, "E_star_ci": [48.0, 53.0], "r_star_ci": [float(r[0]), float(r[4])], "level": 0.9}
    plot_objective(tmp_path / "o.png", r, e_soft, e_soft + 0.3, np.gradient(e_soft, r) * 1e-4, sweep, float(r[0]),
                   param="hfov", scale=SCALE, unit="deg", title=title, **ci)
    _assert_apart_and_inside(drawn[0])
