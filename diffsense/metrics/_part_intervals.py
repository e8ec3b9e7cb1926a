"""Intervals on the breakdown's parts, from the scene sample, at no new evaluation.

Every E-valued part of the breakdown (`_breakdown.py`) is, like E itself, a ratio of sums over
variants (`_intervals.py`): with per-variant numerators num_n and denominators den_n,

    by scenario s:     num_n = [n in s] w_n sum_i sq_ni          den_n = [n in s] w_n I_n
    coverage part k:   num_n = w_n sum_i [i in k] sq_ni           den_n = w_n sum_i [i in k]
    horizon step f:    num_n = w_n sq_err_nf                      den_n = w_n

(sq_ni: the squared distance of instant i, each (draw, instant) one instant under the draws, w_n
the variant's weight), and the part's E at a resample's counts c is sqrt(c.num / c.den). The
interval is the same stratified expanded percentile bootstrap as E's (same resamples, same seed):
a scenario's part is resampled within its own stratum (its tail from its own variants). A
resample that draws no instant of a coverage part leaves the part undefined there; the quantiles
are read over the resamples that define it, and a part no resample defines has none.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np
from jaxtyping import Float, Int

from diffsense.metrics._breakdown import _draws_as_instants
from diffsense.metrics._coverage import coverage_parts
from diffsense.metrics._intervals import LEVEL, RESAMPLES, bootstrap_counts, expanded_tail


@dataclasses.dataclass(frozen=True)
class PartSums:
    """The breakdown's parts as ratios of per-variant sums (module docstring); P parts, N variants.

    Attributes:
        names: [P] each part's place in the breakdown: ("by_scenario", name),
            ("coverage", "throughout" | "partly" | "never") or ("by_horizon", step index).
        num: [P, N] numerators [m^2].
        den: [P, N] denominators (instants, or variant weights per horizon step).
        scenario: [P] the scenario index a part is confined to, -1 for a pooled part.
    """

    names: tuple[tuple[str, Any], ...]
    num: Float[np.ndarray, "P N"]
    den: Float[np.ndarray, "P N"]
    scenario: Int[np.ndarray, " P"]

    def e(self, counts: Float[np.ndarray, "B N"]) -> Float[np.ndarray, "P B"]:
        """Each part's E [m] at each resample's counts; nan where a resample draws none of it."""
        counts = np.asarray(counts, np.float64)
        num, den = self.num @ counts.T, self.den @ counts.T
        defined = den > 0
        return np.where(defined, np.sqrt(np.maximum(num, 0.0) / np.where(defined, den, 1.0)), np.nan)


def part_sums(sq: Float[np.ndarray, "N P"], classes: Float[np.ndarray, "N P 3"], sq_error: Float[np.ndarray, "N F"],
              scenario: Int[np.ndarray, " N"], weight: Float[np.ndarray, " N"],
              scenario_names: Sequence[str]) -> PartSums:
    """The `PartSums` of a breakdown's arrays: instants sq [N, P] with coverage classes [N, P, 3]
    (P instants, or draws x instants) and the horizon steps' sq_error [N, F]."""
    sq, w = np.asarray(sq, np.float64), np.asarray(weight, np.float64)
    scenario = np.asarray(scenario)
    names, num, den, where = [], [], [], []
    for s, name in enumerate(scenario_names):
        mine = (scenario == s) * w
        names.append(("by_scenario", name))
        num.append(mine * np.sum(sq, axis=1))
        den.append(mine * sq.shape[1])
        where.append(s)
    for part, mask in coverage_parts(np.asarray(classes, np.float64)).items():
        names.append(("coverage", part))
        num.append(w * np.sum(sq * mask, axis=1))
        den.append(w * np.sum(mask, axis=1))
        where.append(-1)
    err = np.asarray(sq_error, np.float64)
    for f in range(err.shape[1]):
        names.append(("by_horizon", f))
        num.append(w * err[:, f])
        den.append(w)
        where.append(-1)
    return PartSums(tuple(names), np.stack(num), np.stack(den), np.asarray(where))


def hard_part_sums(hard: Any, scenario: Int[np.ndarray, " N"], weight: Float[np.ndarray, " N"],
                   scenario_names: Sequence[str]) -> PartSums:
    """The `PartSums` of `diffsense.metrics.breakdown`'s parts: of one hard evaluation."""
    return part_sums(hard.sq_instant, hard.coverage, hard.sq_error, scenario, weight, scenario_names)


def drawn_part_sums(parts: Any, scenario: Int[np.ndarray, " N"], weight: Float[np.ndarray, " N"],
                    scenario_names: Sequence[str]) -> PartSums:
    """The `PartSums` of `diffsense.metrics.drawn_breakdown`'s parts: of E_ref's detection draws
    (`DrawnParts`), each (draw, instant) one instant."""
    return part_sums(_draws_as_instants(parts.sq_instant), _draws_as_instants(parts.coverage), parts.sq_error,
                     scenario, weight, scenario_names)


def part_cis(parts: PartSums, strata: Int[np.ndarray, " N"], weight: Float[np.ndarray, " N"], *,
             level: float = LEVEL, resamples: int = RESAMPLES, seed: int = 0) -> list[list[float] | None]:
    """Each part's interval [lo, hi] [m] at `level` (module docstring), None where it cannot be
    estimated (one variant in a stratum, or no resample defines the part)."""
    strata, weight = np.asarray(strata), np.asarray(weight, np.float64)
    counts = bootstrap_counts(strata, weight=weight, resamples=resamples, seed=seed)
    if counts is None:
        return [None] * len(parts.names)
    e = parts.e(counts)
    pooled = expanded_tail(strata, weight, level)
    out = []
    for p, s in enumerate(parts.scenario):
        tail = pooled if s < 0 else expanded_tail(strata[strata == s], weight[strata == s], level)
        finite = e[p][np.isfinite(e[p])]
        out.append(None if finite.size == 0 else [float(q) for q in np.quantile(finite, [tail, 1.0 - tail])])
    return out


def with_part_cis(breakdown: dict[str, Any], parts: PartSums, cis: Sequence[list[float] | None]) -> dict[str, Any]:
    """`breakdown` (the layout of `diffsense.metrics.breakdown`) with each part's interval added
    as "E_ci": in every by_scenario entry and coverage part, and by_horizon's "E_ci" list (one
    per horizon step)."""
    out = dict(breakdown)
    by_scenario = {k: dict(v) for k, v in out["by_scenario"].items()}
    coverage = dict(out["coverage"], parts={k: dict(v) for k, v in out["coverage"]["parts"].items()})
    by_horizon = dict(out["by_horizon"], E_ci=[None] * len(out["by_horizon"]["t_s"]))
    for (where, name), ci in zip(parts.names, cis):
        if where == "by_scenario":
            by_scenario[name]["E_ci"] = ci
        elif where == "coverage":
            coverage["parts"][name]["E_ci"] = ci
        else:
            by_horizon["E_ci"][name] = ci
    return out | {"by_scenario": by_scenario, "coverage": coverage, "by_horizon": by_horizon}


__all__ = ["PartSums", "drawn_part_sums", "hard_part_sums", "part_cis", "part_sums", "with_part_cis"]
