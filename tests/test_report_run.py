"""A run's outputs (`diffsense.report.write_run`): result.json holds the result's content, and the
three figures draw the result's own numbers (its curves, its sweep, r*); without curves only
result.json; nothing else is left in the folder."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
from matplotlib.figure import Figure

from diffsense.report import RUN_FILES, write_run
from diffsense.study import Curves

CONTENT = {"sensor": "radar", "param": "hfov_deg", "r_star": {"hfov_deg": 60.0}, "E_hard_star": 2.0}


def _result(curves: bool = True):
    """A `diffsense.Result` as far as write_run reads it."""
    r = (30.0, 60.0, 90.0)
    c = Curves(r=r, E_soft=(3.0, 2.0, 2.5), E_hard=(3.1, 2.2, 2.4), dE_dr=(-0.1, 0.0, 0.1),
               horizon_gt={"sc01": np.linspace(0.1, 2.5, 25), "sc02": np.linspace(0.2, 3.0, 25)},
               horizon_sensor={s: {x: np.linspace(0.5, 4.0, 25) for x in (30.0, 90.0)} for s in ("sc01", "sc02")},
               horizon_s=tuple(0.2 * np.arange(1, 26)), timeline={30.0: np.ones((5, 2)), 90.0: np.zeros((5, 2))},
               timeline_roles=("target", "lead"), dt_s=0.1)
    sweep = [SimpleNamespace(r=30.0, E_hard=3.1, E_soft=3.0), SimpleNamespace(r=90.0, E_hard=2.4, E_soft=2.5)]
    return SimpleNamespace(to_json=lambda: CONTENT, curves=c if curves else None, param="hfov_deg",
                           units={"hfov_deg": "deg"}, r_star={"hfov_deg": 60.0}, sensor="radar", sweep=sweep,
                           scenarios=("sc01", "sc02"), config={"variants": 1})


def test_write_run_writes_result_json_and_the_three_figures(tmp_path):
    assert write_run(_result(), tmp_path / "out") == CONTENT
    out = tmp_path / "out"
    assert sorted(p.name for p in out.iterdir()) == sorted(RUN_FILES)  # no temporaries
    assert json.loads((out / "result.json").read_text()) == CONTENT
    for name in RUN_FILES[1:4]:
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000
    assert write_run(_result(curves=False), tmp_path / "bare") == CONTENT
    assert sorted(p.name for p in (tmp_path / "bare").iterdir()) == ["report.html", "result.json"]


def test_the_figures_draw_the_result_s_numbers(tmp_path, monkeypatch):
    drawn = []
    monkeypatch.setattr(Figure, "savefig", lambda fig, file, **kw: drawn.append(fig))
    write_run(_result(), tmp_path)
    objective, horizon, timeline = drawn
    soft, hard, sweep, r_star = objective.axes[0].get_lines()
    np.testing.assert_allclose([soft.get_xdata(), soft.get_ydata()], [[30, 60, 90], [3.0, 2.0, 2.5]])
    np.testing.assert_allclose([hard.get_xdata(), hard.get_ydata()], [[30, 60, 90], [3.1, 2.2, 2.4]])
    np.testing.assert_allclose([sweep.get_xdata(), sweep.get_ydata()], [[30, 90], [3.1, 2.4]])
    assert list(r_star.get_xdata()) == [60.0, 60.0] and objective.axes[0].get_xlabel() == "hfov_deg [deg]"
    assert [ax.get_title() for ax in horizon.axes] == ["sc01", "sc02"]
    assert [line.get_label() for line in horizon.axes[0].get_lines()][1:] == ["hfov_deg 30 deg", "hfov_deg 90 deg"]
    assert [ax.get_title() for ax in timeline.axes] == ["hfov_deg 30 deg", "hfov_deg 90 deg"]
    assert [t.get_text() for t in timeline.axes[0].get_yticklabels()] == ["target", "lead"]
    assert all("radar" in f.get_suptitle() for f in drawn)
