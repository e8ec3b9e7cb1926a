"""A run's outputs from a `diffsense.Result`: result.json, the three figures and report.html."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from diffsense.report._figures import (
    plot_detection_timeline,
    plot_objective,
    plot_rmse_horizon,
)
from diffsense.report._html import FIGURES, answer_value, html_report
from diffsense.runtime import write_bytes, write_json

RUN_FILES = ("result.json", "objective.png", "rmse_horizon.png", "detections.png", "report.html")


def write_run(result: Any, folder: str | Path) -> dict[str, Any]:
    """Write result.json, the figures when the result has curves (objective.png, rmse_horizon.png,
    detections.png) and report.html (`html_report`: the page, with those figures embedded) into
    `folder`; returns the result.json content."""
    folder = Path(folder)
    content = result.to_json()
    write_json(folder / "result.json", content)
    figures = {}
    if result.curves is not None:
        _write_figures(result, content, folder)
        # The page embeds the figures as drawn (their PNG bytes, read back from this call's
        # files, never a previous run's), so it is one file that needs nothing beside it.
        figures = {n: (folder / n).read_bytes() for n in FIGURES}
    write_bytes(folder / "report.html", html_report(content, figures).encode("utf-8"))
    return content


def _write_figures(result: Any, content: dict[str, Any], folder: Path) -> None:
    """objective.png, rmse_horizon.png and detections.png from the result's curves; objective.png
    with the intervals result.json (`content`) holds: each sweep step's "E_ci", the answer's
    "E_ci" on its E and "r_star_ci"."""
    c = result.curves
    name, unit = result.param, result.units[result.param]
    variants = result.config.get("variants")
    scenes = f"{', '.join(result.scenarios)} ({variants} variant{'s' if variants != 1 else ''} each)"
    first = f"{result.scenarios[0]}, nominal variant"
    cis = [p.get("E_ci") for p in content.get("sweep") or []]
    cis += [None] * (len(result.sweep) - len(cis))
    sweep = [{"r": p.r, "E_hard": p.E_hard, "E_soft": p.E_soft, "E_ci": ci} for p, ci in zip(result.sweep, cis)]
    plot_objective(folder / "objective.png", c.r, c.E_soft, c.E_hard, c.dE_dr, sweep, result.r_star[name],
                   E_star=answer_value(content), E_star_ci=content.get("E_ci"),
                   r_star_ci=(content.get("r_star_ci") or {}).get(name), level=content.get("ci_level"),
                   param=name, unit=unit, title=f"{result.sensor}: E over {name}, {scenes}")
    curves = {s: {"gt": c.horizon_gt[s], "steps": c.horizon_sensor[s]} for s in c.horizon_gt}
    plot_rmse_horizon(folder / "rmse_horizon.png", curves, param=name, unit=unit,
                      title=f"{result.sensor}: RMSE against the true future per sweep step, {scenes}")
    plot_detection_timeline(folder / "detections.png", c.timeline, c.timeline_roles, dt_s=c.dt_s,
                            param=name, unit=unit, title=f"{result.sensor}: hard detections, {first}")
