"""E broken down: by scenario, by horizon step and by coverage, from one hard evaluation or from
the detection draws of one reference evaluation.

Every part is an instant-weighted piece of the pooled E^2: E^2 = sum over parts of
(share of instants) x (E of the part)^2, for the scenarios and for the coverage classes alike.
Per horizon step, E (Eq. 12: sensor-input against ground-truth-input prediction) and both
predictions' RMSE against the true future (the paper's Figs. 6 and 7 in numbers).

Of the draws (`drawn_breakdown`), each (draw, instant) is one instant of the pool: E_ref^2 is the
mean over draws of each draw's E_hard^2, so a part's E_ref^2 is the mean of its instants' squared
errors over every draw, and an instant belongs to the coverage part its draw put it in. The parts
are then those of E_ref, the value the answer is chosen on, and the shares are expectations over
the draws. The parts' values are keyed by what they are: "E_hard" or "E_ref".
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from diffsense.metrics._coverage import COVERAGE_PARTS, coverage_parts


def _rms(sq: np.ndarray, w: np.ndarray) -> float:
    total = float(np.sum(w))
    return float(np.sqrt(max(float(np.sum(w * sq)) / total, 0.0))) if total > 0 else float("nan")


def _coverage(sq: np.ndarray, classes: np.ndarray, w: np.ndarray, key: str) -> dict[str, Any]:
    total = float(np.sum(w))
    shares = {name: float(np.sum(w * classes[..., k])) / total
              for k, name in enumerate(("at_instant", "in_window", "throughout"))}
    parts = {}
    for name, mask in coverage_parts(classes).items():
        share = float(np.sum(w * mask)) / total
        parts[name] = {"share": share, key: _rms(sq[mask], w[mask]) if share > 0 else None}
    return shares | {"parts": parts}


def _pooled(sq: np.ndarray, classes: np.ndarray, sq_error, sq_true_gt, sq_true_sensor, scenario: np.ndarray,
            weight: np.ndarray, scenario_names: Sequence[str], horizon_s: Sequence[float], key: str) -> dict[str, Any]:
    """The breakdown of instants sq [N, P] with coverage classes [N, P, 3] (P: instants, or
    draws x instants), horizon arrays sq_error [N, F] and sq_true_* [N, I, F]."""
    w = np.broadcast_to(np.asarray(weight, np.float64)[:, None], sq.shape)
    by_scenario = {}
    for s, name in enumerate(scenario_names):
        mine = np.asarray(scenario) == s
        by_scenario[name] = {key: _rms(sq[mine], w[mine]), "coverage": _coverage(sq[mine], classes[mine], w[mine], key),
                             **_tracked_part(sq[mine], classes[mine, ..., 1], w[mine])}
    wn = np.asarray(weight, np.float64)[:, None]
    true_gt, true_sensor = np.asarray(sq_true_gt, np.float64), np.asarray(sq_true_sensor, np.float64)
    wi = np.broadcast_to(wn[..., None], true_gt.shape)
    per_step = float(np.sum(wi[..., 0]))
    return {
        key: _rms(sq, w),
        "by_scenario": by_scenario,
        "coverage": _coverage(sq, classes, w, key),
        "by_horizon": {
            "t_s": [float(t) for t in horizon_s],
            key: list(np.sqrt(np.sum(wn * np.asarray(sq_error, np.float64), axis=0) / np.sum(wn))),
            "rmse_true_gt": list(np.sqrt(np.sum(wi * true_gt, axis=(0, 1)) / per_step)),
            "rmse_true_sensor": list(np.sqrt(np.sum(wi * true_sensor, axis=(0, 1)) / per_step)),
        },
    }


def breakdown(hard: Any, scenario: np.ndarray, weight: np.ndarray, scenario_names: Sequence[str],
              horizon_s: Sequence[float]) -> dict[str, Any]:
    """The breakdown of one hard evaluation (numpy `HardEvaluation` [N, I, ...] arrays).

    Returns {"E_hard", "by_scenario": {name: {"E_hard", "coverage", "E_tracked", "missed_share"}},
    "coverage": {...},
    "by_horizon": {"t_s", "E_hard", "rmse_true_gt", "rmse_true_sensor"}}; coverage holds the
    shares of instants "at_instant", "in_window", "throughout" and "parts": the partition
    {"throughout", "partly", "never"} with each part's share and E_hard [m].
    """
    return _pooled(np.asarray(hard.sq_instant, np.float64), np.asarray(hard.coverage, np.float64), hard.sq_error,
                   hard.sq_true_gt, hard.sq_true_sensor, scenario, weight, scenario_names, horizon_s, "E_hard")


def _draws_as_instants(a: np.ndarray) -> np.ndarray:
    """[K, N, I, ...] -> [N, K * I, ...]: each (draw, instant) one instant of its variant."""
    a = np.moveaxis(np.asarray(a, np.float64), 0, 1)
    return a.reshape(a.shape[0], -1, *a.shape[3:])


def drawn_breakdown(parts: Any, scenario: np.ndarray, weight: np.ndarray, scenario_names: Sequence[str],
                    horizon_s: Sequence[float]) -> dict[str, Any]:
    """The breakdown of E_ref over its detection draws (numpy `DrawnParts`): the layout of
    `breakdown` with "E_ref" where it has "E_hard" (module docstring)."""
    return _pooled(_draws_as_instants(parts.sq_instant), _draws_as_instants(parts.coverage), parts.sq_error,
                   parts.sq_true_gt, parts.sq_true_sensor, scenario, weight, scenario_names, horizon_s, "E_ref")


def _tracked_part(sq: np.ndarray, tracked: np.ndarray, w: np.ndarray) -> dict[str, Any]:
    """E over the instants whose target is tracked (detected in the window) [m] and the share of
    instants that are not, of the instants in `sq` / `tracked` / `w` (same shapes)."""
    seen = float(np.sum(w * tracked))
    e_tracked = float(np.sqrt(float(np.sum(w * tracked * sq)) / seen)) if seen > 0 else None
    return {"E_tracked": e_tracked, "missed_share": 1.0 - seen / float(np.sum(w))}


def _tracked(sq: np.ndarray, tracked: np.ndarray, weight: np.ndarray, miss_penalty_m2: float) -> dict[str, Any]:
    """The tracked question's pieces of K draws' instants (sq, tracked [K, N, I]): E_tracked and
    the missed share pooled over the draws, J the mean of the draws' J [m^2]."""
    w = np.broadcast_to(np.asarray(weight, np.float64)[None, :, None], sq.shape)
    part = _tracked_part(sq, tracked, w)
    seen = np.sum(w * tracked, axis=(1, 2))
    error = np.sum(w * tracked * sq, axis=(1, 2))
    missed = 1.0 - seen / np.sum(w, axis=(1, 2))
    return part | {"J_m2": float(np.mean(error / (1.0 + seen) + miss_penalty_m2 * missed)),
                   "miss_penalty_m2": miss_penalty_m2}


def tracked_summary(hard: Any, weight: np.ndarray, miss_penalty_m2: float) -> dict[str, Any]:
    """The "tracked" question's pieces at one hard evaluation: E over the tracked instants [m],
    the missed share and J [m^2] (with the objective's one pseudo-instant of zero error)."""
    sq = np.asarray(hard.sq_instant, np.float64)[None]
    return _tracked(sq, np.asarray(hard.coverage, np.float64)[None, ..., 1], weight, miss_penalty_m2)


def drawn_tracked_summary(parts: Any, weight: np.ndarray, miss_penalty_m2: float) -> dict[str, Any]:
    """The "tracked" question's pieces over E_ref's detection draws (numpy `DrawnParts`): J is
    the mean of the draws' J, E_ref of the "tracked" question squared."""
    sq = np.asarray(parts.sq_instant, np.float64)
    return _tracked(sq, np.asarray(parts.coverage, np.float64)[..., 1], weight, miss_penalty_m2)


__all__ = ["COVERAGE_PARTS", "breakdown", "drawn_breakdown", "drawn_tracked_summary", "tracked_summary"]
