"""The case study's tables (markdown) and the paper's three statements, from the JSON that
`benchmarks/case_study.py` writes (`diffsense case-study FILE... [--figure-dir DIR]`
prints them; docs/case-study.md holds that output):

    diffsense case-study benchmarks/results/case_study_shipped.json \
        benchmarks/results/case_study_ngsim.json --figure-dir docs/img

Each profile is read with its own fill (physical: hold, paper: zero, the paper's raw pipeline);
the radar imputation table shows all three fills. Both questions: Eq. 12 pooled (E_hard) and the
"tracked" one (E over the instants whose target is detected in the 3 s window, beside the share
of instants that are not).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

from diffsense.report._figures import plot_rmse_horizon
from diffsense.runtime import InputError

PROFILE_FILL = {"physical": "hold", "paper": "zero"}


def index_runs(data: list[dict]) -> dict:
    return {(r["weights"], r["profile"], r["sensor"], r["fill"]): r for d in data for r in d["runs"]}


def _table(header: list[str], rows: list[list]) -> str:
    cell = lambda v: f"{v:.2f}" if isinstance(v, float) else str(v)  # noqa: E731
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join(lines + ["| " + " | ".join(cell(v) for v in row) + " |" for row in rows])


def _best(values: list[float], steps: list[float], tol_m: float = 0.01) -> str:
    """The step(s) within tol_m of the smallest value: "30", or "60-180" for a flat run."""
    low = [r for r, v in zip(steps, values) if v <= min(values) + tol_m]
    return f"{low[0]:g}" if len(low) == 1 else f"{low[0]:g}-{low[-1]:g}"


def pooled(runs: dict, weights: list[str], steps: list[float]) -> str:
    rows = []
    for (w, profile, sensor, fill), run in runs.items():
        if fill != PROFILE_FILL[profile]:
            continue
        e = [s["E_hard"] for s in run["steps"]]
        t = [s["tracked"]["E_tracked"] for s in run["steps"]]
        m = [s["tracked"]["missed_share"] for s in run["steps"]]
        rows.append([w, profile, sensor, "E_hard"] + e + [_best(e, steps)])
        rows.append(["", "", "", "E_tracked"] + t + [_best(t, steps)])
        rows.append(["", "", "", "missed share"] + m + [""])
    return _table(["weights", "profile", "sensor", "[m]"] + [f"{r:g} deg" for r in steps] + ["best"], rows)


def per_scenario(runs: dict, steps: list[float]) -> str:
    rows = []
    for (w, profile, sensor, fill), run in runs.items():
        if fill != PROFILE_FILL[profile]:
            continue
        for name in run["scenarios"]:
            e = [s["by_scenario"][name]["E_hard"] for s in run["steps"]]
            worst = steps[max(range(len(e)), key=e.__getitem__)]
            flat = max(e) - min(e) < 0.01
            rows.append([w, profile, sensor, name] + e + ["flat" if flat else _best(e, steps), "" if flat else f"{worst:g}"])
    return _table(["weights", "profile", "sensor", "scenario"] + [f"{r:g}" for r in steps] + ["best", "worst"], rows)


def imputation(runs: dict, steps: list[float]) -> str:
    rows = []
    for (w, profile, sensor, fill), run in runs.items():
        if sensor == "radar":
            rows.append([w, profile, fill] + [s["E_hard"] for s in run["steps"]])
    return _table(["weights", "profile", "fill"] + [f"{r:g} deg" for r in steps], rows)


def ground_truth(data: list[dict]) -> str:
    rows = []
    for d in data:
        run = next(r for r in d["runs"])
        for i, name in enumerate(run["scenarios"]):
            gt = run["rmse_gt"][i]
            rows.append([run["weights"], name] + [gt[k] for k in (4, 9, 14, 19, 24)])
        rows.append([run["weights"], "card / published"] + list(d["validation_rmse_m"][run["weights"]]))
    return _table(["weights", "scenario", "1 s", "2 s", "3 s", "4 s", "5 s"], rows)


def statements(runs: dict, weights: list[str], steps: list[float]) -> str:
    out = []
    for w in weights:
        for profile, fill in PROFILE_FILL.items():
            radar = [s["E_hard"] for s in runs[(w, profile, "radar", fill)]["steps"]]
            camera = [s["E_hard"] for s in runs[(w, profile, "camera", fill)]["steps"]]
            wins = sum(r < c for r, c in zip(radar, camera))
            best = _best(radar, steps)
            c_worst = steps[max(range(len(camera)), key=camera.__getitem__)]
            spread = max(camera[1:]) - min(camera[1:])
            out.append(f"- {w}, {profile}: (1) radar below camera at {wins} of {len(steps)} steps; (2) radar's best "
                       f"step(s) {best} deg (30 deg: {radar[0]:.2f} m, best {min(radar):.2f} m); (3) camera's worst "
                       f"step {c_worst:g} deg, spread above {steps[0]:g} deg {spread:.2f} m")
    return "\n".join(out)


def figure(path: str, runs: dict, key: tuple) -> None:
    """The paper's Fig. 6/7 for one run: per scenario, RMSE against the true future at each
    horizon step, ground-truth input (black) and sensor input at each HFOV step."""
    run = runs[key]
    curves = {name: {"gt": run["rmse_gt"][i], "steps": {s["r"]: s["rmse_sensor"][i] for s in run["steps"]}}
              for i, name in enumerate(run["scenarios"])}
    plot_rmse_horizon(path, curves, param="HFOV", unit="deg", title=" / ".join(key))


def print_case_study(paths: Sequence[str], figure_dirs: Sequence[str] = ()) -> int:
    """Print the case study's tables from `benchmarks/case_study.py`'s results files, and write
    Figs. 6 and 7 (for the first weights, each profile with its fill) into each of `figure_dirs`."""
    figures = list(figure_dirs)
    data = [_load(p) for p in paths]
    runs = index_runs(data)
    weights = list(dict.fromkeys(w for w, *_ in runs))
    steps = data[0]["steps_deg"]
    m = data[0]["machine"]
    print(f"Computed by benchmarks/case_study.py on jax {m['jax']} ({m['backend']}, {m['cpus']} CPU cores), "
          f"{data[0]['variants']} variants per scenario.\n")
    for title, text in (("Pooled, both questions", pooled(runs, weights, steps)),
                        ("E_hard per scenario", per_scenario(runs, steps)),
                        ("Radar imputation: E_hard per fill", imputation(runs, steps)),
                        ("Ground-truth-input RMSE against the true future [m]", ground_truth(data)),
                        ("The paper's three statements", statements(runs, weights, steps))):
        print(f"### {title}\n\n{text}\n")
    for folder in figures:  # Figs. 6 and 7 for the first weights, each profile with its fill
        for profile, fill in PROFILE_FILL.items():
            for sensor in ("radar", "camera"):
                figure(f"{folder}/case_{sensor}_{profile}_{weights[0]}.png", runs, (weights[0], profile, sensor, fill))
    return 0


def _load(path: str) -> dict:
    """One results file of `benchmarks/case_study.py` (InputError if it is not JSON)."""
    text = Path(path).read_text()  # a missing file: OSError, one line under `run`
    try:
        return json.loads(text)
    except ValueError as e:
        raise InputError(f"{path}: not a results file: {e}") from None
