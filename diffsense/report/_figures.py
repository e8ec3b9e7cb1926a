"""The run's figures, written atomically as PNG.

- objective.png: E_soft and E_hard over r, the sweep's points and r*, dE/dr on a second axis;
  the intervals as error bars (each step, the answer's E) and a band (r*) where the run has them.
- rmse_horizon.png: the paper's Figs 6/7: per-horizon RMSE (0.2 .. 5 s) against the true
  future for every sweep step and for ground-truth inputs, one panel per scenario.
- detection timeline: the paper's Figs 8/9: p_detect over time of the target and its
  neighbours, one panel per r value.

Figures are built on `matplotlib.figure.Figure` (Agg canvas, no pyplot): nothing global is
touched and nothing needs closing. `scale` and `unit` convert r for display. Margins are fixed in
inches (`_place`) rather than solved by a layout engine: constrained layout measures every tick
label before it places the axes, about half of the horizon figure's drawing time.
"""

from __future__ import annotations

import math
import numbers
import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from diffsense.runtime import save_figure

# The predictor's horizon: 25 points at 5 Hz (0.2 .. 5 s).
HORIZON_DT_S = 0.2
_DPI = 120


# Margins [in]: room for tick labels and an axis label on the left and below, a panel title on
# top, a legend row, a figure title; gaps between panels hold both neighbours' labels.
_LEFT_IN, _RIGHT_IN, _TOP_IN, _BOTTOM_IN = 0.75, 0.2, 0.35, 0.7
_TWIN_RIGHT_IN = 0.85
_SUPTITLE_IN, _LEGEND_ROW_IN = 0.3, 0.2
_WSPACE_IN, _HSPACE_IN = 0.85, 0.75


def _place(fig: Figure, *, legend_rows: int, title: bool, right_in: float = _RIGHT_IN) -> None:
    """Fix the subplot grid's margins in inches, leaving `legend_rows` legend rows at the bottom
    (and a row for the figure title when `title`)."""
    width_in, height_in = fig.get_size_inches()
    bottom_in = _BOTTOM_IN + _LEGEND_ROW_IN * legend_rows
    top_in = _TOP_IN + (_SUPTITLE_IN if title else 0.0)
    nrows, ncols = fig.axes[0].get_subplotspec().get_gridspec().get_geometry()
    panel_w = (width_in - _LEFT_IN - right_in - _WSPACE_IN * (ncols - 1)) / ncols
    panel_h = (height_in - bottom_in - top_in - _HSPACE_IN * (nrows - 1)) / nrows
    fig.subplots_adjust(left=_LEFT_IN / width_in, right=1.0 - right_in / width_in,
                        bottom=bottom_in / height_in, top=1.0 - top_in / height_in,
                        wspace=_WSPACE_IN / panel_w, hspace=_HSPACE_IN / panel_h)


def _label(key: Any, scale: float, unit: str) -> str:
    """A step's legend text: a number (numpy's too) scaled and with its unit, anything else as is."""
    if isinstance(key, numbers.Real) and not isinstance(key, bool):
        return f"{float(key) * scale:g}{' ' + unit if unit else ''}"
    return str(key)


def plot_objective(
    path: str | os.PathLike[str],
    r: Sequence[float],
    E_soft: Sequence[float],
    E_hard: Sequence[float],
    dE_dr: Sequence[float],
    sweep: Sequence[Mapping[str, float]],
    r_star: float,
    *,
    E_star: float | None = None,
    E_star_ci: Sequence[float] | None = None,
    r_star_ci: Sequence[float] | None = None,
    level: float | None = None,
    param: str = "r",
    scale: float = 1.0,
    unit: str = "",
    title: str = "",
) -> None:
    """objective.png: E_soft(r), E_hard(r) [m] with the sweep and r*, dE/dr on a twin axis.

    Only evaluated points are drawn as data: E_hard as markers (it is piecewise constant between
    evaluations, with steps nobody evaluated), E_soft and dE/dr as markers joined by thin lines
    that the legend calls interpolation. The legend sits outside the axes. Where the run has
    intervals (result.json's "E_ci", "sweep[i].E_ci", "r_star_ci"), each sweep step's is an error
    bar on its E, the answer's E at r* is a marker with its own, and r*'s interval is a band
    across the axes; a missing (None) interval draws nothing in its place.

    Args:
        r, E_soft, E_hard, dE_dr: [n] curves over r (the objective's units; dE/dr in m per unit).
        sweep: [{"r", "E_hard", "E_soft", "E_ci" (optional [lo, hi] [m] or None)}] the stepped sweep.
        r_star: the answer.
        E_star, E_star_ci: the answer's E [m] (what result.json's "E_ci" is on) and its [lo, hi];
            drawn only with both.
        r_star_ci: [lo, hi] of r* (the objective's units), or None.
        level: the intervals' level (0.9), for the legend.
        param, scale, unit: x-axis name and display conversion (dE/dr is divided by scale).
    """
    x = np.asarray(r, dtype=float) * scale
    fig = Figure(figsize=(7.5, 5.0))
    ax = fig.add_subplot()
    ax.plot(x, E_soft, color="C0", marker=".", linewidth=0.8, label="E soft (lines: interpolated)")
    ax.plot(x, E_hard, linestyle="none", color="C1", marker="x", label="E hard (evaluated points)")
    sweep_r = [p["r"] * scale for p in sweep]
    ax.plot(sweep_r, [p["E_hard"] for p in sweep], "o", color="C1", label="sweep (hard)")
    r_star_label = f"r* = {_label(r_star, scale, unit)}"
    ax.axvline(r_star * scale, color="C3", linestyle="--", label=r_star_label)
    _draw_intervals(ax, sweep, r_star, E_star, E_star_ci, r_star_ci, level, scale)
    ax.set_xlabel(f"{param} [{unit}]" if unit else param)
    ax.set_ylabel("E_RMSE [m]")
    twin = ax.twinx()
    slope = np.asarray(dE_dr, dtype=float) / scale
    twin.plot(x, slope, color="C2", alpha=0.6, marker=".", linewidth=0.8, label="dE/dr soft (lines: interpolated)")
    twin.axhline(0.0, color="C2", linewidth=0.5)
    twin.set_ylabel(f"dE/d{param} [m/{unit}]" if unit else f"dE/d{param}")
    handles = ax.get_legend_handles_labels()
    twin_handles = twin.get_legend_handles_labels()
    labels = handles[1] + twin_handles[1]
    fig.legend(handles[0] + twin_handles[0], labels, fontsize=8, loc="lower center", ncol=3)
    if title:
        fig.suptitle(title, fontsize=10)
    _place(fig, legend_rows=math.ceil(len(labels) / 3), title=bool(title), right_in=_TWIN_RIGHT_IN)
    save_figure(fig, path, dpi=_DPI)


def _interval(ci: Any) -> tuple[float, float] | None:
    """[lo, hi] as two finite floats, or None (a null, short or non-finite interval)."""
    if ci is None or len(ci) != 2:
        return None
    lo, hi = (float(v) if isinstance(v, numbers.Real) else math.nan for v in ci)
    return (lo, hi) if math.isfinite(lo) and math.isfinite(hi) else None


def _draw_intervals(ax: Any, sweep: Sequence[Mapping[str, Any]], r_star: float, E_star: float | None,
                    E_star_ci: Sequence[float] | None, r_star_ci: Sequence[float] | None,
                    level: float | None, scale: float) -> None:
    """The sweep's error bars, the answer's E with its interval and r*'s band (plot_objective)."""
    what = f"{level:.0%} interval" if isinstance(level, numbers.Real) and math.isfinite(level) else "interval"
    # Each interval a vertical bar from lo to hi at its r (an expanded percentile interval need
    # not be centred on E, so the ends are drawn as they are, not as E -/+ a length).
    steps = [(p["r"] * scale, ci) for p in sweep if (ci := _interval(p.get("E_ci"))) is not None]
    if steps:
        ax.vlines([x for x, _ in steps], [c[0] for _, c in steps], [c[1] for _, c in steps],
                  color="C1", linewidth=1.5, label=f"sweep {what}")
    star_ci = _interval(E_star_ci)
    if star_ci is not None and E_star is not None and math.isfinite(float(E_star)):
        ax.vlines([r_star * scale], [star_ci[0]], [star_ci[1]], color="C3", linewidth=2.0,
                  label=f"E at r* with its {what}")
        ax.plot([r_star * scale], [float(E_star)], "D", color="C3", markersize=5, label="_E at r*")
    band = _interval(r_star_ci)
    if band is not None:
        ax.axvspan(band[0] * scale, band[1] * scale, color="C3", alpha=0.12, linewidth=0, label=f"r* {what}")


def plot_rmse_horizon(
    path: str | os.PathLike[str],
    curves: Mapping[str, Mapping[str, Any]],
    *,
    param: str = "r",
    scale: float = 1.0,
    unit: str = "",
    title: str = "",
) -> None:
    """rmse_horizon.png: per-horizon RMSE [m] per sweep step vs ground-truth inputs (every
    horizon step is evaluated: the lines join evaluated points 0.2 s apart).

    Args:
        curves: scenario -> {"gt": [H] RMSE from ground-truth inputs,
                             "steps": {r (number) or label: [H] RMSE from sensor inputs}};
            H = 25 horizon points 0.2 .. 5 s. Two panels a row (the paper pairs RLC / LLC).
        param, scale, unit: legend labels of the steps.
    """
    names = list(curves)
    if not names:
        raise ValueError("no scenarios to plot")
    ncols = min(2, len(names))
    nrows = math.ceil(len(names) / ncols)
    fig = Figure(figsize=(max(5.0 * ncols, 8.0), 3.2 * nrows + 1.0))
    axes = fig.subplots(nrows, ncols, squeeze=False)
    for ax, name in zip(axes.flat, names):
        gt = np.asarray(curves[name]["gt"], dtype=float)
        t = HORIZON_DT_S * np.arange(1, gt.size + 1)
        ax.plot(t, gt, color="k", linewidth=2.0, label="ground truth")
        for i, (key, rmse) in enumerate(curves[name]["steps"].items()):
            label = f"{param} {_label(key, scale, unit)}"
            ax.plot(t, np.asarray(rmse, dtype=float), color=f"C{i % 10}", label=label)
        ax.set_title(name, fontsize=10)
        ax.set_xlabel("prediction horizon [s]")
        ax.set_ylabel("RMSE [m]")
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(names):]:
        ax.set_visible(False)
    handles, labels = axes.flat[0].get_legend_handles_labels()
    ncol = min(len(labels), 4)
    fig.legend(handles, labels, fontsize=7, loc="lower center", ncol=ncol)
    if title:
        fig.suptitle(title, fontsize=10)
    _place(fig, legend_rows=math.ceil(len(labels) / ncol), title=bool(title))
    save_figure(fig, path, dpi=_DPI)


def plot_detection_timeline(
    path: str | os.PathLike[str],
    p_detect: Mapping[Any, Any],
    roles: Sequence[str],
    *,
    dt_s: float = 0.1,
    param: str = "r",
    scale: float = 1.0,
    unit: str = "",
    title: str = "",
) -> None:
    """The detection timeline: p_detect of each vehicle over time, one panel per r.

    Args:
        p_detect: r (number) or label -> [T, V] detection probabilities in [0, 1].
        roles: [V] a name per vehicle column ("target", "lead", ...), bottom to top.
        dt_s: frame period [s].
        param, scale, unit: panel titles.
    """
    keys = list(p_detect)
    if not keys:
        raise ValueError("no detection timelines to plot")
    fig = Figure(figsize=(7.0, 0.5 + 0.35 * len(roles) * len(keys) + 0.6 * len(keys)))
    axes = fig.subplots(len(keys), 1, squeeze=False, sharex=True)[:, 0]
    for ax, key in zip(axes, keys):
        p = np.clip(np.asarray(p_detect[key], dtype=float), 0.0, 1.0)
        if p.ndim != 2 or p.shape[1] != len(roles):
            raise ValueError(f"p_detect[{key!r}] has shape {p.shape}, expected [T, {len(roles)}]")
        t = dt_s * np.arange(p.shape[0])
        for v in range(p.shape[1]):
            band = v + 0.8 * p[:, v]
            ax.fill_between(t, v, band, step="mid", color=f"C{v % 10}", alpha=0.8, linewidth=0)
        ax.set_yticks(np.arange(len(roles)) + 0.4, list(roles), fontsize=8)
        ax.set_ylim(-0.1, len(roles))
        ax.set_title(f"{param} {_label(key, scale, unit)}", fontsize=9)
    axes[-1].set_xlabel("time [s]  (band height = detection probability)")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    save_figure(fig, path, dpi=_DPI)
