"""How sure the one-parameter answer is: intervals on E from the scene sample and paired
comparisons of the sweep's steps, read from the evaluations the job made (no program of its own).

Every E the sweep and the answer report gets a percentile bootstrap interval
(`diffsense.metrics.bootstrap_ci`: variants resampled within each scenario, B resamples fixed by
the problem's seed). Every step is compared with the best step (and r*, where it is no step,
too) by the interval of their difference, paired: every r sees the same scenes, so each resample
reweights both alike. A comparison whose interval holds 0 cannot be told apart with these scenes;
those steps, with the best, are the near-optimal set the data supports. Recorded scenes are each a
scenario of one variant: they are resampled as one sample instead.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from diffsense.metrics import LEVEL, RESAMPLES, SceneSums, bootstrap_ci, difference_ci, estimable
from diffsense.runtime import to_host
from diffsense.solve import Evaluator

METHOD = "stratified expanded percentile bootstrap over scene variants"


def strata(ev: Evaluator, recorded: bool) -> tuple[np.ndarray, np.ndarray]:
    """The variants' strata [N] (their scenario; one stratum for recorded scenes) and weights [N]."""
    E = ev.objective
    scenario, weight = to_host((E.data.scenario, E.data.weight))
    scenario = np.asarray(scenario)
    return (np.zeros_like(scenario) if recorded else scenario), np.asarray(weight)


def verdict(a: str, b: str, diff: float, ci: tuple[float, float] | None) -> str:
    """A comparison in plain words: a is worse or better than b by diff [lo, hi], or the two
    cannot be told apart (the interval holds 0), or the interval cannot be estimated."""
    if ci is None:
        return f"{a} against {b}: {diff:+.2f} m, no interval with one variant per scenario"
    lo, hi = ci
    if lo > 0:
        return f"{a} is worse than {b} by {diff:.2f} m [{lo:.2f}, {hi:.2f}]"
    if hi < 0:
        return f"{a} is better than {b} by {-diff:.2f} m [{-hi:.2f}, {-lo:.2f}]"
    return f"{a} and {b} cannot be told apart with these scenes ({diff:+.2f} m [{lo:.2f}, {hi:.2f}])"


def _pair(a: str, b: str, e_a: float, e_b: float, s_a: SceneSums, s_b: SceneSums, groups: np.ndarray,
          seed: int) -> dict[str, Any]:
    ci = difference_ci(s_a, s_b, groups, level=LEVEL, resamples=RESAMPLES, seed=seed)
    unpaired = difference_ci(s_a, s_b, groups, paired=False, level=LEVEL, resamples=RESAMPLES, seed=seed)
    diff = e_a - e_b
    return {"a": a, "b": b, "diff_m": diff, "ci": None if ci is None else list(ci),
            "ci_unpaired": None if unpaired is None else list(unpaired), "paired": True,
            "verdict": verdict(a, b, diff, ci)}


def line_intervals(ev: Evaluator, result: Any, e_star: float, *, of_reference: bool, seed: int, unit: str,
                   recorded: bool = False) -> dict[str, Any]:
    """result.json's interval keys of a one-parameter job: "ci_level", "ci_method", "E_ci" (of
    the answer's E, `e_star` [m]), "sweep_E_ci" (one per sweep step), "comparisons" and
    "indistinguishable" (the steps the data cannot tell from the best; None without intervals).
    `of_reference`: the answer is judged on E_ref (a probabilistic law), not E_hard."""
    groups, weight = strata(ev, recorded)
    ok = estimable(groups, weight)
    note = None if ok else ("no interval from the scene sample: a scenario with one variant says nothing "
                            "about how E moves with other traffic (two or more variants per scenario give one)")
    method = {"method": METHOD, "resamples": RESAMPLES, "strata": "none" if recorded else "scenario",
              "seed": int(seed), "note": note}
    steps = [p.r for p in result.sweep]
    values = {p.r: float(p.E_hard) for p in result.sweep} | {result.r_star: float(e_star)}
    sums = {r: ev.scene_sums(r, of_reference) for r in values}
    if any(s is None for s in sums.values()):  # a custom objective's reference keeps no draws
        method["note"] = "no interval: the objective's reference keeps no per-variant parts"
        return {"ci_level": LEVEL, "ci_method": method, "E_ci": None, "sweep_E_ci": [None] * len(steps),
                "comparisons": [], "indistinguishable": None}

    def ci(r):
        out = bootstrap_ci(sums[r], groups, level=LEVEL, resamples=RESAMPLES, seed=seed)
        return None if out is None else list(out)

    best = min(steps, key=lambda r: values[r]) if steps else result.r_star
    label = {r: f"{r:.5g} {unit}".strip() for r in values}
    label[result.r_star] = label[result.r_star] if result.r_star in steps else f"r* {label[result.r_star]}"
    others = [r for r in steps if r != best] + ([result.r_star] if result.r_star not in steps else [])
    comparisons = [_pair(label[r], label[best], values[r], values[best], sums[r], sums[best], groups, seed)
                   for r in others]
    same = None if not ok else sorted(
        [best] + [r for r, c in zip(others, comparisons) if r in steps and c["ci"][0] <= 0.0 <= c["ci"][1]])
    return {"ci_level": LEVEL, "ci_method": method, "E_ci": ci(result.r_star), "sweep_E_ci": [ci(r) for r in steps],
            "comparisons": comparisons, "indistinguishable": same}
