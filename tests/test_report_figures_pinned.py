"""What the run's figures draw, caught before saving: every curve's points in display units
(r times the scale, dE/dr divided by it), the labels, legends and titles, the panels' layout and
margins in inches, the detection bands' heights, and the refusals of empty or misshapen input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from matplotlib.colors import to_rgba

from diffsense.report import _figures
from diffsense.report._figures import plot_detection_timeline, plot_objective, plot_rmse_horizon

SCALE = 180.0 / math.pi  # the objective's radians shown as degrees


@pytest.fixture
def drawn(monkeypatch):
    """The (figure, path, dpi) each plot saves, caught on the way to the file."""
    figures = []
    monkeypatch.setattr(_figures, "save_figure", lambda fig, path, dpi: figures.append((fig, path, dpi)))
    return figures


def _xy(line):
    return np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)


def _margins_in(fig):
    """(left, right, bottom, top) margins of the subplot grid [in]."""
    w, h = fig.get_size_inches()
    p = fig.subplotpars
    return p.left * w, (1 - p.right) * w, p.bottom * h, (1 - p.top) * h


OBJECTIVE = {"r": [0.5, 1.0, 1.5], "E_soft": [3.0, 2.0, 2.5], "E_hard": [3.1, 2.2, 2.4], "dE_dr": [-2.0, 0.5, 1.0],
             "sweep": [{"r": 0.5, "E_hard": 3.1, "E_soft": 3.0}, {"r": 1.5, "E_hard": 2.4, "E_soft": 2.5}],
             "r_star": 1.0}


def test_the_objective_figure_draws_its_curves_in_display_units(drawn):
    plot_objective("out/objective.png", **OBJECTIVE, param="hfov", scale=SCALE, unit="deg")
    ((fig, path, dpi),) = drawn
    assert path == "out/objective.png" and dpi == 120 and tuple(fig.get_size_inches()) == (7.5, 5.0)
    ax, twin = fig.axes
    soft, hard, sweep, r_star = ax.get_lines()
    x = np.array([0.5, 1.0, 1.5]) * SCALE
    np.testing.assert_allclose(_xy(soft), [x, [3.0, 2.0, 2.5]])
    np.testing.assert_allclose(_xy(hard), [x, [3.1, 2.2, 2.4]])
    np.testing.assert_allclose(_xy(sweep), [[0.5 * SCALE, 1.5 * SCALE], [3.1, 2.4]])
    np.testing.assert_allclose(r_star.get_xdata(), [SCALE, SCALE])
    assert (soft.get_marker(), soft.get_linestyle(), soft.get_linewidth()) == (".", "-", 0.8)
    assert (hard.get_marker(), hard.get_linestyle()) == ("x", "None")
    assert (sweep.get_marker(), sweep.get_linestyle()) == ("o", "None")
    assert [to_rgba(line.get_color()) for line in (soft, hard, sweep, r_star)] == [to_rgba(c) for c in ("C0", "C1", "C1", "C3")]
    assert r_star.get_linestyle() == "--"
    slope, zero = twin.get_lines()
    np.testing.assert_allclose(_xy(slope), [x, np.array([-2.0, 0.5, 1.0]) / SCALE])  # [m/deg]
    np.testing.assert_allclose(zero.get_ydata(), [0.0, 0.0])
    assert [to_rgba(line.get_color()) for line in (slope, zero)] == [to_rgba("C2")] * 2
    assert (slope.get_marker(), slope.get_linestyle()) == (".", "-")
    assert (ax.get_xlabel(), ax.get_ylabel(), twin.get_ylabel()) == ("hfov [deg]", "E_RMSE [m]", "dE/dhfov [m/deg]")
    (legend,) = fig.legends
    assert [t.get_text() for t in legend.get_texts()] == [
        "E soft (lines: interpolated)", "E hard (evaluated points)", "sweep (hard)", "r* = 57.2958 deg",
        "dE/dr soft (lines: interpolated)"]
    assert legend._ncols == 3 and legend.get_texts()[0].get_fontsize() == 8
    assert fig._suptitle is None
    # Two legend rows of three below the axes, the twin axis's labels on the right, no title row.
    np.testing.assert_allclose(_margins_in(fig), [0.75, 0.85, 0.7 + 2 * 0.2, 0.35])


def test_the_objective_figure_without_a_unit_and_with_a_title(drawn):
    plot_objective("o.png", **OBJECTIVE, param="width_px", title="camera")
    ((fig, _, _),) = drawn
    ax, twin = fig.axes
    np.testing.assert_allclose(ax.get_lines()[0].get_xdata(), [0.5, 1.0, 1.5])
    assert (ax.get_xlabel(), twin.get_ylabel()) == ("width_px", "dE/dwidth_px")
    assert fig.legends[0].get_texts()[3].get_text() == "r* = 1"
    assert fig._suptitle.get_text() == "camera" and fig._suptitle.get_fontsize() == 10
    np.testing.assert_allclose(_margins_in(fig)[3], 0.35 + 0.3)


def test_the_figures_defaults_name_r_in_its_own_units(drawn):
    plot_objective("o.png", **OBJECTIVE)
    plot_rmse_horizon("h.png", {"RLC": {"gt": GT, "steps": {0.5: GT}}})
    plot_detection_timeline("d.png", {0.5: np.ones((3, 1))}, ["target"])
    (objective, _, _), (horizon, _, _), (timeline, _, _) = drawn
    ax, twin = objective.axes
    assert (ax.get_xlabel(), twin.get_ylabel()) == ("r", "dE/dr")
    np.testing.assert_allclose(ax.get_lines()[0].get_xdata(), [0.5, 1.0, 1.5])
    assert [f._suptitle for f in (objective, horizon, timeline)] == [None] * 3
    assert horizon.axes[0].get_lines()[1].get_label() == "r 0.5"
    assert timeline.axes[0].get_title() == "r 0.5"
    vertices = timeline.axes[0].collections[0].get_paths()[0].vertices
    assert vertices[:, 0].max() == pytest.approx(0.2)  # three frames 0.1 s apart


GT = np.linspace(0.1, 2.5, 25)


def _curves(n: int) -> dict:
    return {f"scenario {i}": {"gt": GT + i, "steps": {0.5: 2 * GT + i, "paper": 3 * GT + i}} for i in range(n)}


def test_the_horizon_figure_draws_one_panel_a_scenario_two_a_row(drawn):
    plot_rmse_horizon("h.png", _curves(3), param="hfov", scale=SCALE, unit="deg")
    ((fig, path, dpi),) = drawn
    assert (path, dpi) == ("h.png", 120) and tuple(fig.get_size_inches()) == (10.0, 3.2 * 2 + 1.0)
    panels = fig.axes
    assert [ax.get_visible() for ax in panels] == [True, True, True, False]
    t = 0.2 * np.arange(1, 26)
    for i, ax in enumerate(panels[:3]):
        gt, step, paper = ax.get_lines()
        np.testing.assert_allclose(_xy(gt), [t, GT + i])
        np.testing.assert_allclose(_xy(step), [t, 2 * GT + i])
        np.testing.assert_allclose(_xy(paper), [t, 3 * GT + i])
        assert (to_rgba(gt.get_color()), gt.get_linewidth()) == (to_rgba("k"), 2.0)
        assert [to_rgba(line.get_color()) for line in (step, paper)] == [to_rgba("C0"), to_rgba("C1")]
        assert [line.get_label() for line in (gt, step, paper)] == ["ground truth", "hfov 28.6479 deg", "hfov paper"]
        assert (ax.get_title(), ax.get_xlabel(), ax.get_ylabel()) == (f"scenario {i}", "prediction horizon [s]", "RMSE [m]")
        assert ax.get_title("center") and ax.title.get_fontsize() == 10
    (legend,) = fig.legends
    assert [x.get_text() for x in legend.get_texts()] == ["ground truth", "hfov 28.6479 deg", "hfov paper"]
    assert legend._ncols == 3 and legend.get_texts()[0].get_fontsize() == 7
    assert fig._suptitle is None
    np.testing.assert_allclose(_margins_in(fig), [0.75, 0.2, 0.7 + 0.2, 0.35])
    # Gaps between panels [in]: 0.85 across, 0.75 down.
    left, right, bottom, top = _margins_in(fig)
    panel_w = (10.0 - left - right - 0.85) / 2
    panel_h = (7.4 - bottom - top - 0.75) / 2
    np.testing.assert_allclose([fig.subplotpars.wspace * panel_w, fig.subplotpars.hspace * panel_h], [0.85, 0.75])


def test_one_scenario_is_one_panel_and_a_long_legend_wraps_at_four(drawn):
    curves = {"RLC": {"gt": GT, "steps": {k: GT for k in (1.0, 2.0, 3.0, 4.0, 5.0)}}}
    plot_rmse_horizon("h.png", curves, title="radar")
    ((fig, _, _),) = drawn
    assert tuple(fig.get_size_inches()) == (8.0, 4.2) and len(fig.axes) == 1
    assert [line.get_label() for line in fig.axes[0].get_lines()][1:] == ["r 1", "r 2", "r 3", "r 4", "r 5"]
    assert fig.legends[0]._ncols == 4 and fig._suptitle.get_text() == "radar"
    np.testing.assert_allclose(_margins_in(fig)[2:], [0.7 + 2 * 0.2, 0.35 + 0.3])  # 6 labels: two rows


def test_numpy_numbers_are_scaled_like_python_numbers(drawn):
    curves = {"RLC": {"gt": GT, "steps": {np.int64(2): GT, np.float32(0.5): GT, 3: GT}}}
    plot_rmse_horizon("h.png", curves, param="hfov", scale=10.0, unit="deg")
    labels = [line.get_label() for line in drawn[0][0].axes[0].get_lines()][1:]
    assert labels == ["hfov 20 deg", "hfov 5 deg", "hfov 30 deg"]


def test_the_detection_timeline_draws_bands_as_tall_as_the_probability(drawn):
    roles = ["target", "lead", "follower"]
    p = {0.5: np.array([[0.0, 0.5, 1.0], [0.25, 1.5, -0.5], [1.0, 0.5, 0.0], [0.5, 0.5, 0.5]]), "paper": np.full((4, 3), 0.5),
         1.0: np.zeros((4, 3))}
    plot_detection_timeline("d.png", p, roles, dt_s=0.2, param="hfov", scale=SCALE, unit="deg", title="radar")
    ((fig, path, dpi),) = drawn
    assert (path, dpi) == ("d.png", 120)
    np.testing.assert_allclose(fig.get_size_inches(), [7.0, 0.5 + 0.35 * 3 * 3 + 0.6 * 3])
    top, bottom, last = fig.axes
    assert [ax.get_title() for ax in (top, bottom, last)] == ["hfov 28.6479 deg", "hfov paper", "hfov 57.2958 deg"]
    bands = top.collections
    assert len(bands) == 3
    for v, band in enumerate(bands):
        vertices = np.concatenate([path.vertices for path in band.get_paths()])
        clipped = np.clip(p[0.5][:, v], 0.0, 1.0)
        assert vertices[:, 1].min() == pytest.approx(v)
        assert vertices[:, 1].max() == pytest.approx(v + 0.8 * clipped.max())
        assert vertices[:, 0].min() == pytest.approx(0.0) and vertices[:, 0].max() == pytest.approx(0.6)
        assert to_rgba(band.get_facecolor()[0])[:3] == to_rgba(f"C{v}")[:3]
    assert {float(y) for y in bottom.collections[2].get_paths()[0].vertices[:, 1]} == {2.0, 2.4}
    # Steps held half a frame either side of each frame's time, not lines between frames.
    x_steps = np.unique(np.round(np.concatenate([p.vertices[:, 0] for p in bands[0].get_paths()]), 9))
    np.testing.assert_allclose(x_steps, [0.0, 0.1, 0.3, 0.5, 0.6])
    np.testing.assert_allclose(top.get_yticks(), [0.4, 1.4, 2.4])
    assert [t.get_text() for t in top.get_yticklabels()] == roles
    assert top.get_ylim() == (-0.1, 3.0)
    assert [ax.get_xlabel() for ax in (top, bottom, last)] == ["", "", "time [s]  (band height = detection probability)"]
    assert top.get_shared_x_axes().joined(top, last)
    assert fig._suptitle.get_text() == "radar"


@pytest.mark.parametrize("call, message", [
    (lambda: plot_rmse_horizon("h.png", {}), "no scenarios to plot"),
    (lambda: plot_detection_timeline("d.png", {}, ["target"]), "no detection timelines to plot"),
    (lambda: plot_detection_timeline("d.png", {30.0: np.zeros((5, 3))}, ["target", "lead"]),
     "p_detect[30.0] has shape (5, 3), expected [T, 2]"),
    (lambda: plot_detection_timeline("d.png", {"a": np.zeros(5)}, ["target"]), "p_detect['a'] has shape (5,), expected [T, 1]"),
])
def test_empty_or_misshapen_input_is_refused_by_whole_message(drawn, call, message):
    with pytest.raises(ValueError) as e:
        call()
    assert str(e.value) == message and drawn == []
