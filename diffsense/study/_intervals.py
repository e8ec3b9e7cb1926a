"""How sure the one-parameter answer is: intervals on E from the scene sample and paired
comparisons of the sweep's steps, read from the evaluations the job made (no program of its own),
and r*'s interval, for which E is evaluated at more points where the resamples' picks fall.

Every E the sweep and the answer report gets a percentile bootstrap interval
(`diffsense.metrics.bootstrap_ci`: variants resampled within each scenario, B resamples fixed by
the problem's seed). Every step is compared with the best step (and r*, where it is no step,
too) by the interval of their difference, paired: every r sees the same scenes, so each resample
reweights both alike. A comparison whose interval holds 0 cannot be told apart with these scenes;
those steps, with the best, are the near-optimal set the data supports. Recorded scenes are each a
scenario of one variant: they are resampled as one sample instead.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from diffsense.metrics import (
    LEVEL,
    RESAMPLES,
    SceneSums,
    bootstrap_ci,
    difference_ci,
    estimable,
    part_cis,
    with_part_cis,
)
from diffsense.runtime import to_host
from diffsense.solve import Evaluator
from diffsense.study._r_star import CONDITIONAL_CAVEAT, box_r_star_interval, r_star_interval

METHOD = "stratified expanded percentile bootstrap over scene variants"
# Measured by benchmarks/bench_r_star_coverage.py (docs/uncertainty.md): on E_hard the interval
# covers the large-sample r* in 22-50 % of seeds, against 95-98 % on E_ref.
THRESHOLD_CAVEAT = ("a lower bound: on E_hard (each detection at its median) the minimiser sits at the edge where "
                    "a far target drops out of range, and no resample holds such an edge earlier than the sample's "
                    "own, so the interval covers less than its level (docs/uncertainty.md)")


def strata(ev: Evaluator, recorded: bool) -> tuple[np.ndarray, np.ndarray]:
    """The variants' strata [N] (their scenario; one stratum for recorded scenes) and weights [N]."""
    E = ev.objective
    scenario, weight = to_host((E.data.scenario, E.data.weight))
    scenario = np.asarray(scenario)
    return (np.zeros_like(scenario) if recorded else scenario), np.asarray(weight)


def _method(estimated: bool, seed: int, recorded: bool) -> dict[str, Any]:
    """result.json's "ci_method": how the intervals are made, and why there are none where not `estimated`."""
    note = None if estimated else ("no interval from the scene sample: a scenario with one variant says nothing "
                                   "about how E moves with other traffic (two or more variants per scenario give one)")
    return {"method": METHOD, "resamples": RESAMPLES, "strata": "none" if recorded else "scenario",
            "seed": int(seed), "note": note}


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


def paired_comparison(a: str, b: str, e_a: float, e_b: float, s_a: SceneSums, s_b: SceneSums, groups: np.ndarray,
                      seed: int, of: str = "sweep") -> dict[str, Any]:
    """a against b, two evaluations over the same variants (`s_a`, `s_b` their `SceneSums`,
    `groups` [N] the strata, `e_a`, `e_b` their E [m]): result.json's comparison {"a", "b",
    "diff_m", "ci", "ci_unpaired", "paired", "of", "verdict"}, the interval of E(a) - E(b)
    paired scene by scene beside the unpaired one (null where it cannot be estimated)."""
    ci = difference_ci(s_a, s_b, groups, level=LEVEL, resamples=RESAMPLES, seed=seed)
    unpaired = difference_ci(s_a, s_b, groups, paired=False, level=LEVEL, resamples=RESAMPLES, seed=seed)
    diff = e_a - e_b
    return {"a": a, "b": b, "diff_m": diff, "ci": None if ci is None else list(ci),
            "ci_unpaired": None if unpaired is None else list(unpaired), "paired": True, "of": of,
            "verdict": verdict(a, b, diff, ci)}


def line_intervals(ev: Evaluator, result: Any, e_star: float, *, of_reference: bool, seed: int, unit: str,
                   interval: tuple[float, float], recorded: bool = False) -> dict[str, Any]:
    """result.json's interval keys of a one-parameter job: "ci_level", "ci_method", "E_ci" (of
    the answer's E, `e_star` [m]), "sweep_E_ci" (one per sweep step), "r_star_ci" ([lo, hi] on
    r*, `r_star_interval`), "comparisons" and "indistinguishable" (the steps the data cannot tell
    from the best; None without intervals); and, for `modality_comparisons` (not result.json),
    "answer_sums" (the answer's `SceneSums`) and "strata". `of_reference`: the answer is judged
    on E_ref (a probabilistic law), not E_hard."""
    groups, weight = strata(ev, recorded)
    ok = estimable(groups, weight)
    method = _method(ok, seed, recorded)
    steps = [p.r for p in result.sweep]
    values = {p.r: float(p.E_hard) for p in result.sweep} | {result.r_star: float(e_star)}
    sums = {r: ev.scene_sums(r, of_reference) for r in values}
    if any(s is None for s in sums.values()):  # a custom objective's reference keeps no draws
        method["note"] = "no interval: the objective's reference keeps no per-variant parts"
        return {"ci_level": LEVEL, "ci_method": method, "E_ci": None, "sweep_E_ci": [None] * len(steps),
                "r_star_ci": None, "comparisons": [], "indistinguishable": None, "answer_sums": None,
                "strata": groups}

    def ci(r):
        out = bootstrap_ci(sums[r], groups, level=LEVEL, resamples=RESAMPLES, seed=seed)
        return None if out is None else list(out)

    best = min(steps, key=lambda r: values[r]) if steps else result.r_star
    label = {r: f"{r:.5g} {unit}".strip() for r in values}
    label[result.r_star] = label[result.r_star] if result.r_star in steps else f"r* {label[result.r_star]}"
    others = [r for r in steps if r != best] + ([result.r_star] if result.r_star not in steps else [])
    comparisons = [paired_comparison(label[r], label[best], values[r], values[best], sums[r], sums[best], groups, seed)
                   for r in others]
    same = None if not ok else sorted(
        [best] + [r for r, c in zip(others, comparisons) if r in steps and c["ci"][0] <= 0.0 <= c["ci"][1]])
    r_ci, resolution, evaluated = r_star_interval(ev, groups, of_reference=of_reference, seed=seed,
                                                  interval=interval)
    method |= {"r_star": "argmin over the evaluated points, made dense where the resamples' picks fall, "
                         "each resample reweighting them alike",
               "r_star_points": evaluated, "r_star_resolution": resolution,
               "r_star_caveat": None if of_reference or r_ci is None else THRESHOLD_CAVEAT}
    return {"ci_level": LEVEL, "ci_method": method, "E_ci": ci(result.r_star), "sweep_E_ci": [ci(r) for r in steps],
            "r_star_ci": r_ci, "comparisons": comparisons, "indistinguishable": same,
            "answer_sums": sums[result.r_star], "strata": groups}


def breakdown_intervals(ev: Evaluator, r: float, breakdown: dict[str, Any], *, of_reference: bool, seed: int,
                        recorded: bool = False) -> dict[str, Any]:
    """`breakdown` (the evaluator's at r) with every E-valued part's interval, "E_ci" in each
    scenario's entry and coverage part and a per-step "E_ci" list in by_horizon
    (`diffsense.metrics.part_cis`, the resamples of E's own interval). Unchanged where the
    objective keeps no per-variant parts (a custom one's reference)."""
    parts = ev.part_sums(r, of_reference)
    if parts is None:
        return breakdown
    groups, weight = strata(ev, recorded)
    return with_part_cis(breakdown, parts, part_cis(parts, groups, weight, level=LEVEL, resamples=RESAMPLES,
                                                    seed=seed))


def answer_ci(ev: Evaluator, r: Any, *, seed: int, recorded: bool = False,
              of_reference: bool = True) -> list[float] | None:
    """The interval [lo, hi] [m] on E_ref at r (E_hard under a deterministic law, or where not
    `of_reference`) from the scene sample of `ev`'s objective; None where it cannot be estimated."""
    sums = ev.scene_sums(r, of_reference)
    if sums is None:
        return None
    out = bootstrap_ci(sums, strata(ev, recorded)[0], level=LEVEL, resamples=RESAMPLES, seed=seed)
    return None if out is None else list(out)


def box_intervals(ev: Evaluator, x: Any, default: Any, *, of_reference: bool, seed: int, recorded: bool = False,
                  bounds: Sequence[tuple[float, float]] | None = None,
                  offset_at: Callable[[np.ndarray], float] | None = None) -> dict[str, Any]:
    """result.json's interval keys of a many-parameter answer at x: "ci_level", "ci_method",
    "E_ci" of the answer's E (E_ref under a probabilistic law, else E_hard), "r_star_ci" ({name:
    [lo, hi]} per parameter along its axis through x, the others held there
    (`box_r_star_interval`, `bounds` in `ev.objective.names` order, `offset_at(x)` the cost term
    of J [m]); null without `bounds` or where it cannot be estimated) and "comparisons": the
    answer against the default suite (`default`, the sensors' defaults clipped to the box),
    paired over the same scenes. Evaluates E at the default, and along the axes, where the solve
    did not."""
    groups, weight = strata(ev, recorded)
    ok = estimable(groups, weight)
    method = _method(ok, seed, recorded) | {"r_star": "not estimated" + (
        "" if bounds is not None else ": ask for it (BoxConfig(r_star_axes=True), --r-star-axes), at up to 25 "
        "evaluations of E per parameter")}
    e = ev.e_reference if of_reference else ev.e_hard
    sums = (ev.scene_sums(x, of_reference), ev.scene_sums(default, of_reference))
    if any(s is None for s in sums):
        method["note"] = "no interval: the objective's reference keeps no per-variant parts"
        return {"ci_level": LEVEL, "ci_method": method, "E_ci": None, "r_star_ci": None, "comparisons": []}
    ci = bootstrap_ci(sums[0], groups, level=LEVEL, resamples=RESAMPLES, seed=seed)
    against = paired_comparison("r*", "the default suite", e(x), e(default), *sums, groups, seed, of="default")
    r_ci = None
    if ok and bounds is not None:
        names = ev.objective.names
        axes = box_r_star_interval(ev, x, bounds, groups, of_reference=of_reference, seed=seed, offset_at=offset_at)
        r_ci = {n: a[0] for n, a in zip(names, axes)}
        caveat = CONDITIONAL_CAVEAT + ("" if of_reference else "; and " + THRESHOLD_CAVEAT)
        method |= {"r_star": "per parameter, argmin of J along its axis through r* (the others held at r*), "
                             "made dense where the resamples' picks fall, each resample reweighting the points alike",
                   "r_star_points": {n: a[2] for n, a in zip(names, axes)},
                   "r_star_resolution": {n: a[1] for n, a in zip(names, axes)}, "r_star_caveat": caveat}
    return {"ci_level": LEVEL, "ci_method": method, "E_ci": None if ci is None else list(ci), "r_star_ci": r_ci,
            "comparisons": [against]}


def _answer_e(result: Any) -> float:
    ref = result.reference or {}
    return float(ref["E_ref_star"] if ref.get("answer_on") == "E_ref" else result.E_hard_star)


def _answer_label(result: Any) -> str:
    if result.param is None:
        return result.sensor
    return f"{result.sensor} at {result.r_star[result.param]:.5g} {result.units[result.param]}".strip()


def modality_comparisons(results: dict[str, Any]) -> list[dict[str, Any]]:
    """Sensor against sensor (`--sensor both`: radar against camera): the first result's answer
    against each other's, {"a", "b", "diff_m", "ci", "ci_unpaired", "paired", "of", "verdict"}
    as in result.json's "comparisons" ("of": "sensors"), diff_m the difference of the answers'
    E (E_ref under a probabilistic law, E_hard under the threshold law) [m], each sensor at its
    own r*. The runs share their scenes (same traffic and seed), so the difference is paired
    scene by scene. A result without per-variant sums (a many-parameter solve, a custom
    objective, one variant per scenario) or over other scenes is left out."""
    def sums(r):
        ci = getattr(r, "intervals", None) or {}
        return ci.get("answer_sums"), ci.get("strata"), (ci.get("ci_method") or {}).get("seed")

    names = list(results)
    out = []
    for b in names[1:]:
        (s_a, g_a, seed), (s_b, g_b, _) = sums(results[names[0]]), sums(results[b])
        if (s_a is None or s_b is None or not np.array_equal(g_a, g_b)
                or not np.array_equal(s_a.instants, s_b.instants) or not estimable(g_a, s_a.instants)):
            continue
        ra, rb = results[names[0]], results[b]
        out.append(paired_comparison(_answer_label(ra), _answer_label(rb), _answer_e(ra), _answer_e(rb), s_a, s_b,
                                     g_a, seed, of="sensors"))
    return out


def with_modality_comparisons(results: dict[str, Any]) -> dict[str, Any]:
    """`results` (sensor name -> `Result`) with `modality_comparisons` added to each one's
    "comparisons" (result.json's), after the sweep's; unchanged where there is none."""
    paired = modality_comparisons(results)
    if not paired:
        return dict(results)
    return {name: dataclasses.replace(r, intervals=r.intervals | {"comparisons": r.intervals["comparisons"] + paired})
            for name, r in results.items()}
