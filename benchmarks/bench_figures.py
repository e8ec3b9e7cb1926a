"""Benchmark: drawing and saving the main job's three figures.

    python benchmarks/bench_figures.py [--repeats 7]

Each figure is drawn with the main job's shapes (6 scenarios, 6 sweep steps, 25 horizon points;
21 evaluated points of E(r); a detection timeline of 2 r values x 201 frames x 4 vehicles) from
fixed synthetic numbers, and written as PNG into a temporary folder, the figures in turn in each
round. Prints the median and minimum over --repeats rounds, after one round that is not counted
(it loads fonts and matplotlib's lazy modules).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from diffsense.report import (
    plot_detection_timeline,
    plot_objective,
    plot_rmse_horizon,
)

STEPS_DEG = (30.0, 60.0, 90.0, 120.0, 150.0, 180.0)
TITLE = "radar: E over hfov_deg, 6 scenarios x 8 variants"


def _figures(folder: Path):
    rng = np.random.default_rng(0)
    r = np.linspace(30.0, 180.0, 21)
    e_soft = 49.0 + 0.06 * (r - 30.0) + rng.normal(0.0, 0.1, r.size)
    sweep = [{"r": s, "E_hard": 50.0 + 0.06 * (s - 30.0), "E_soft": 49.0 + 0.06 * (s - 30.0)} for s in STEPS_DEG]
    gt = np.linspace(0.1, 8.0, 25)
    curves = {f"sc0{i}": {"gt": gt, "steps": {s: gt * rng.uniform(1.0, 2.0) for s in STEPS_DEG}} for i in range(1, 7)}
    timeline = {s: (rng.uniform(size=(201, 4)) > 0.3).astype(float) for s in (30.0, 180.0)}
    roles = ("target", "lead", "target_lead", "adjacent")
    return {
        "objective.png": lambda: plot_objective(folder / "objective.png", r, e_soft, e_soft + 1.0, np.gradient(e_soft, r),
                                                sweep, 30.0, param="hfov_deg", unit="deg", title=TITLE),
        "rmse_horizon.png": lambda: plot_rmse_horizon(folder / "rmse_horizon.png", curves, param="hfov_deg",
                                                      unit="deg", title=TITLE),
        "detections.png": lambda: plot_detection_timeline(folder / "detections.png", timeline, roles, param="hfov_deg",
                                                          unit="deg", title=TITLE),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        figures = _figures(Path(tmp))
        times: dict[str, list[float]] = {name: [] for name in figures}
        for round_ in range(args.repeats + 1):
            for name, draw in figures.items():
                start = time.perf_counter()
                draw()
                if round_:
                    times[name].append(time.perf_counter() - start)
    print(f"| figure | median [s] | min [s] |   ({args.repeats} rounds)")
    print("|---|---|---|")
    for name, t in times.items():
        print(f"| {name} | {statistics.median(t):.3f} | {min(t):.3f} |")
    total = [sum(ts) for ts in zip(*times.values())]
    print(f"| all three | {statistics.median(total):.3f} | {min(total):.3f} |")


if __name__ == "__main__":
    main()
