"""The case study's tables (markdown) and the paper's three statements, from the JSON that
`benchmarks/case_study.py` writes (`diffsense case-study FILE... [--figure-dir DIR]`
prints them; docs/case-study.md holds that output):

    diffsense case-study benchmarks/results/case_study_shipped.json \
        benchmarks/results/case_study_ngsim.json --figure-dir docs/img

Each profile is read with its own fill (physical: hold, paper: zero, the paper's raw pipeline);
the radar imputation table shows all three fills. Both questions: Eq. 12 pooled (E_hard) and the
"tracked" one (E over the instants whose target is detected in the 3 s window, beside the share
of instants that are not). Where the file holds intervals from the scene sample (each step's
"E_ci", each run's and the file's "comparisons"), the pooled table gains each E_hard's 90 %
interval, a table gives every step against its run's best step and radar against camera, paired,
and the statements say which differences the scenes can tell apart; a file without them is read
as before.
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


def _ci(ci) -> str:
    return "none" if ci is None else f"[{ci[0]:.2f}, {ci[1]:.2f}]"


def _diff(c: dict) -> str:
    """A comparison's difference and its paired interval: "+2.83 [2.10, 3.50]"."""
    return f"{c['diff_m']:+.2f} {_ci(c['ci'])}"


def _clear(c: dict, tol_m: float = 0.01) -> bool:
    """The scenes tell the two apart: the paired interval excludes 0, and the difference is at
    least `tol_m` (the tables' "best"; below it, steps with the same tracks differ by float
    rounding alone)."""
    return c.get("ci") is not None and (c["ci"][0] > 0 or c["ci"][1] < 0) and abs(c["diff_m"]) >= tol_m


def pooled(runs: dict, weights: list[str], steps: list[float]) -> str:
    rows = []
    for (w, profile, sensor, fill), run in runs.items():
        if fill != PROFILE_FILL[profile]:
            continue
        e = [s["E_hard"] for s in run["steps"]]
        t = [s["tracked"]["E_tracked"] for s in run["steps"]]
        m = [s["tracked"]["missed_share"] for s in run["steps"]]
        rows.append([w, profile, sensor, "E_hard"] + e + [_best(e, steps)])
        if any("E_ci" in s for s in run["steps"]):
            rows.append(["", "", "", "90% CI"] + [_ci(s.get("E_ci")) for s in run["steps"]] + [""])
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


def against_best(runs: dict, steps: list[float]) -> str:
    """Every step against its run's best step (each profile with its own fill): E(step) -
    E(best) [m] with its paired 90 % interval; "best" at the best step."""
    rows = []
    for (w, profile, sensor, fill), run in runs.items():
        if fill != PROFILE_FILL[profile] or "comparisons" not in run:
            continue
        by_step = {c["a"]: c for c in run["comparisons"]}
        rows.append([w, profile, sensor] + [_diff(by_step[f"{r:g} deg"]) if f"{r:g} deg" in by_step else "best"
                                            for r in steps])
    return _table(["weights", "profile", "sensor"] + [f"{r:g} deg" for r in steps], rows)


def radar_against_camera(comparisons: list[dict], steps: list[float]) -> str:
    """Radar against camera at each step: E(radar) - E(camera) [m] with its paired 90 % interval."""
    rows = {}
    for c in comparisons:
        rows.setdefault((c["weights"], c["profile"]), {})[c["r"]] = _diff(c)
    return _table(["weights", "profile"] + [f"{r:g} deg" for r in steps],
                  [[w, p] + [cells.get(r, "") for r in steps] for (w, p), cells in rows.items()])


def statements(runs: dict, weights: list[str], steps: list[float], comparisons: list[dict] | None = None) -> str:
    """The paper's three statements for each weights and profile; with the file's radar-against-
    camera `comparisons` and the runs' own, how many of the differences the scenes tell apart."""
    out = []
    for w in weights:
        for profile, fill in PROFILE_FILL.items():
            if (w, profile, "radar", fill) not in runs or (w, profile, "camera", fill) not in runs:
                continue  # a file of one profile, or one sensor, has no statement for the other
            run = runs[(w, profile, "radar", fill)]
            radar = [s["E_hard"] for s in run["steps"]]
            camera = [s["E_hard"] for s in runs[(w, profile, "camera", fill)]["steps"]]
            wins = sum(r < c for r, c in zip(radar, camera))
            paired = [c for c in comparisons or [] if (c["weights"], c["profile"]) == (w, profile)]
            clear_wins = f" ({sum(_clear(c) and c['diff_m'] < 0 for c in paired)} by more than the paired 90 % " \
                         "interval)" if paired else ""
            best = _best(radar, steps)
            told = f"; worse by more than the paired interval at {sum(map(_clear, run['comparisons']))} of " \
                   f"{len(run['comparisons'])} other steps" if "comparisons" in run else ""
            c_worst = steps[max(range(len(camera)), key=camera.__getitem__)]
            spread = max(camera[1:]) - min(camera[1:])
            out.append(f"- {w}, {profile}: (1) radar below camera at {wins} of {len(steps)} steps{clear_wins}; "
                       f"(2) radar's best step(s) {best} deg (30 deg: {radar[0]:.2f} m, best {min(radar):.2f} m{told}); "
                       f"(3) camera's worst step {c_worst:g} deg, spread above {steps[0]:g} deg {spread:.2f} m")
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
    comparisons = [c for d in data for c in d.get("comparisons", [])]
    print(f"Computed by benchmarks/case_study.py on jax {m['jax']} ({m['backend']}, {m['cpus']} CPU cores), "
          f"{data[0]['variants']} variants per scenario.\n")
    sections = [("Pooled, both questions", pooled(runs, weights, steps)),
                ("E_hard per scenario", per_scenario(runs, steps)),
                ("Radar imputation: E_hard per fill", imputation(runs, steps)),
                ("Ground-truth-input RMSE against the true future [m]", ground_truth(data))]
    if any("comparisons" in r for r in runs.values()):
        sections.append(("Each step against its run's best, paired: E_hard(step) - E_hard(best) [m], 90% interval",
                         against_best(runs, steps)))
    if comparisons:
        sections.append(("Radar against camera, paired: E_hard(radar) - E_hard(camera) [m], 90% interval",
                         radar_against_camera(comparisons, steps)))
    sections.append(("The paper's three statements", statements(runs, weights, steps, comparisons)))
    for title, text in sections:
        print(f"### {title}\n\n{text}\n")
    for folder in figures:  # Figs. 6 and 7 for the first weights, each profile with its fill
        for profile, fill in PROFILE_FILL.items():
            for sensor in ("radar", "camera"):
                if (weights[0], profile, sensor, fill) not in runs:
                    continue
                figure(f"{folder}/case_{sensor}_{profile}_{weights[0]}.png", runs, (weights[0], profile, sensor, fill))
    return 0


def _load(path: str) -> dict:
    """One results file of `benchmarks/case_study.py` (InputError if it is not JSON)."""
    text = Path(path).read_text()  # a missing file: OSError, one line under `run`
    try:
        return json.loads(text)
    except ValueError as e:
        raise InputError(f"{path}: not a results file: {e}") from None
