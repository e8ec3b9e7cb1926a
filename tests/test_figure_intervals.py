"""objective.png's intervals (`diffsense.report.write_run`, `plot_objective`): where result.json
holds them, each sweep step's "E_ci" is a bar at its r whose ends are result.json's numbers, the
answer's "E_ci" a bar at r* on the answer's E (E_ref(r*) under a probabilistic law) and
"r_star_ci" a band across the axes; null intervals (one variant per scenario) draw the figure as
it is without them."""

from __future__ import annotations

import math
import re
from types import SimpleNamespace

import numpy as np
import pytest
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from diffsense.report import html_report, plot_objective, write_run
from diffsense.study import Curves

SWEEP = [{"r": 30.0, "E_hard": 3.1, "E_soft": 3.0, "E_ci": [2.85, 3.42]},
         {"r": 60.0, "E_hard": 2.2, "E_soft": 2.0, "E_ci": [2.05, 2.31]},
         {"r": 90.0, "E_hard": 2.4, "E_soft": 2.5, "E_ci": [2.41, 2.77]}]  # an interval need not hold E


def _content(intervals: bool, on_ref: bool = False) -> dict:
    """result.json of a one-parameter run, as far as write_run reads it."""
    none = not intervals
    return {"sensor": "radar", "param": "hfov_deg", "units": {"hfov_deg": "deg"}, "r_star": {"hfov_deg": 66.0},
            "E_hard_star": 2.15, "E_soft_star": 2.0, "ci_level": 0.9,
            "reference": {"answer_on": "E_ref" if on_ref else "E_hard", "E_ref_star": 2.5 if on_ref else 2.15},
            "E_ci": None if none else [2.02, 2.27], "r_star_ci": None if none else {"hfov_deg": [48.0, 81.5]},
            "sweep": [p | {"E_ci": None} if none else p for p in SWEEP]}


def _result(content: dict):
    """A `diffsense.Result` as far as write_run reads it."""
    c = Curves(r=(30.0, 60.0, 90.0), E_soft=(3.0, 2.0, 2.5), E_hard=(3.1, 2.2, 2.4), dE_dr=(-0.1, 0.0, 0.1),
               horizon_gt={"sc01": np.linspace(0.1, 2.5, 25)}, horizon_sensor={"sc01": {30.0: np.linspace(0.5, 4.0, 25)}},
               horizon_s=tuple(0.2 * np.arange(1, 26)), timeline={30.0: np.ones((5, 2))},
               timeline_roles=("target", "lead"), dt_s=0.1)
    sweep = [SimpleNamespace(r=p["r"], E_hard=p["E_hard"], E_soft=p["E_soft"]) for p in SWEEP]
    return SimpleNamespace(to_json=lambda: content, curves=c, param="hfov_deg", units={"hfov_deg": "deg"},
                           r_star={"hfov_deg": 66.0}, sensor="radar", sweep=sweep, scenarios=("sc01",),
                           config={"variants": 4})


@pytest.fixture
def drawn(monkeypatch):
    """Each figure saved instead of its bytes."""
    figures = []
    monkeypatch.setattr(Figure, "savefig", lambda fig, file, **kw: figures.append(fig))
    return figures


def _bars(ax) -> list[np.ndarray]:
    """Each vertical-bar collection's segments, [n, 2 ends, (x, y)], in drawing order."""
    return [np.asarray(c.get_segments(), float) for c in ax.collections if isinstance(c, LineCollection)]


def _bands(ax) -> list[tuple[float, float]]:
    """The x extents of the spans drawn across the axes."""
    return [(p.get_x(), p.get_x() + p.get_width()) for p in ax.patches if isinstance(p, Rectangle)]


@pytest.mark.parametrize("on_ref", [False, True])
def test_each_interval_is_drawn_with_result_json_s_ends(drawn, tmp_path, on_ref):
    content = _content(intervals=True, on_ref=on_ref)
    write_run(_result(content), tmp_path)
    ax = drawn[0].axes[0]
    steps, star = _bars(ax)
    for (bottom, top), p in zip(steps, content["sweep"]):
        assert bottom[0] == top[0] == p["r"]  # a vertical bar at the step
        assert [bottom[1], top[1]] == p["E_ci"]  # its ends exactly result.json's numbers
    assert len(steps) == len(content["sweep"])
    assert star.tolist() == [[[66.0, content["E_ci"][0]], [66.0, content["E_ci"][1]]]]
    # The answer's E as a marker at r*: E_ref(r*) where the answer is chosen on it.
    marker = [line for line in ax.get_lines() if line.get_marker() == "D"]
    assert [list(m.get_xdata()) + list(m.get_ydata()) for m in marker] == [[66.0, content["reference"]["E_ref_star"]
                                                                           if on_ref else content["E_hard_star"]]]
    assert _bands(ax) == [pytest.approx(tuple(content["r_star_ci"]["hfov_deg"]))]
    labels = [t.get_text() for t in drawn[0].legends[0].get_texts()]
    assert {"sweep 90% interval", "E at r* with its 90% interval", "r* 90% interval"} <= set(labels)


def test_null_intervals_draw_the_figure_as_without_them(drawn, tmp_path):
    write_run(_result(_content(intervals=False)), tmp_path / "null")
    write_run(_result({k: v for k, v in _content(intervals=False).items()
                       if k not in ("E_ci", "r_star_ci", "ci_level", "sweep")}), tmp_path / "older")
    for fig in (drawn[0], drawn[3]):  # objective.png of each run (three figures a run)
        ax = fig.axes[0]
        assert _bars(ax) == [] and _bands(ax) == []
        soft, hard, sweep, r_star = ax.get_lines()  # the four curves, nothing more
        np.testing.assert_allclose(sweep.get_ydata(), [3.1, 2.2, 2.4])
        assert not any("interval" in t.get_text() for t in fig.legends[0].get_texts())
    assert (tmp_path / "null" / "objective.png").exists()


def test_plot_objective_scales_the_intervals_and_skips_the_missing_ones(drawn, tmp_path):
    scale = 180.0 / math.pi
    sweep = [{"r": 0.5, "E_hard": 3.1, "E_soft": 3.0, "E_ci": [2.9, 3.3]},
             {"r": 1.0, "E_hard": 2.2, "E_soft": 2.0, "E_ci": None},
             {"r": 1.5, "E_hard": 2.4, "E_soft": 2.5, "E_ci": [float("nan"), 2.6]}]
    plot_objective(tmp_path / "o.png", [0.5, 1.0, 1.5], [3.0, 2.0, 2.5], [3.1, 2.2, 2.4], [0.0] * 3, sweep, 1.2,
                   E_star=2.1, E_star_ci=None, r_star_ci=[1.1, 1.3], level=0.9, scale=scale, unit="deg")
    ax = drawn[0].axes[0]
    (steps,) = _bars(ax)  # only the step with a finite interval; no answer bar without E_ci
    np.testing.assert_allclose(steps, [[[0.5 * scale, 2.9], [0.5 * scale, 3.3]]])
    assert not [line for line in ax.get_lines() if line.get_marker() == "D"]
    assert _bands(ax) == [pytest.approx((1.1 * scale, 1.3 * scale))]  # r*'s band in display units


def _svg_bars(page: str) -> int:
    """The chart's vertical error bars (stroke-width 2 lines; the axes are thinner)."""
    return len(re.findall(r'<line [^>]*stroke-width="2"/>', page))


@pytest.mark.parametrize("intervals", [True, False])
def test_report_html_s_chart_has_a_bar_per_interval_and_r_star_s_band(intervals):
    content = _content(intervals) | {"interval": [30.0, 180.0]}
    page = html_report(content)
    assert _svg_bars(page) == (len(SWEEP) + 1 if intervals else 0)  # each step and the answer
    assert page.count('class="r-star-ci"') == (1 if intervals else 0)
