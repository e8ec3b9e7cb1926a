"""E broken down: by scenario, by horizon step and by coverage, from one hard evaluation.

Every part is an instant-weighted piece of the pooled E^2: E^2 = sum over parts of
(share of instants) x (E of the part)^2, for the scenarios and for the coverage classes alike.
Per horizon step, E (Eq. 12: sensor-input against ground-truth-input prediction) and both
predictions' RMSE against the true future (the paper's Figs. 6 and 7 in numbers).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from diffsense.metrics._coverage import COVERAGE_PARTS, coverage_parts


def _rms(sq: np.ndarray, w: np.ndarray) -> float:
    total = float(np.sum(w))
    return float(np.sqrt(max(float(np.sum(w * sq)) / total, 0.0))) if total > 0 else float("nan")


def _coverage(sq: np.ndarray, classes: np.ndarray, w: np.ndarray) -> dict[str, Any]:
    total = float(np.sum(w))
    shares = {name: float(np.sum(w * classes[..., k])) / total
              for k, name in enumerate(("at_instant", "in_window", "throughout"))}
    parts = {}
    for name, mask in coverage_parts(classes).items():
        share = float(np.sum(w * mask)) / total
        parts[name] = {"share": share, "E_hard": _rms(sq[mask], w[mask]) if share > 0 else None}
    return shares | {"parts": parts}


def breakdown(hard: Any, scenario: np.ndarray, weight: np.ndarray, scenario_names: Sequence[str],
              horizon_s: Sequence[float]) -> dict[str, Any]:
    """The breakdown of one hard evaluation (numpy `HardEvaluation` [N, I, ...] arrays).

    Returns {"E_hard", "by_scenario": {name: {"E_hard", "coverage", "E_tracked", "missed_share"}},
    "coverage": {...},
    "by_horizon": {"t_s", "E_hard", "rmse_true_gt", "rmse_true_sensor"}}; coverage holds the
    shares of instants "at_instant", "in_window", "throughout" and "parts": the partition
    {"throughout", "partly", "never"} with each part's share and E_hard [m].
    """
    sq = np.asarray(hard.sq_instant, np.float64)  # [N, I]
    classes = np.asarray(hard.coverage, np.float64)  # [N, I, 3]
    w = np.broadcast_to(np.asarray(weight, np.float64)[:, None], sq.shape)
    by_scenario = {}
    for s, name in enumerate(scenario_names):
        mine = np.asarray(scenario) == s
        by_scenario[name] = {"E_hard": _rms(sq[mine], w[mine]), "coverage": _coverage(sq[mine], classes[mine], w[mine]),
                             **_tracked_part(sq[mine], classes[mine, ..., 1], w[mine])}
    wn = np.asarray(weight, np.float64)[:, None]
    wi = w[..., None]
    return {
        "E_hard": _rms(sq, w),
        "by_scenario": by_scenario,
        "coverage": _coverage(sq, classes, w),
        "by_horizon": {
            "t_s": [float(t) for t in horizon_s],
            "E_hard": list(np.sqrt(np.sum(wn * np.asarray(hard.sq_error), axis=0) / np.sum(wn))),
            "rmse_true_gt": list(np.sqrt(np.sum(wi * np.asarray(hard.sq_true_gt), axis=(0, 1)) / np.sum(w))),
            "rmse_true_sensor": list(np.sqrt(np.sum(wi * np.asarray(hard.sq_true_sensor), axis=(0, 1)) / np.sum(w))),
        },
    }


def _tracked_part(sq: np.ndarray, tracked: np.ndarray, w: np.ndarray) -> dict[str, Any]:
    """E over the instants whose target is tracked (detected in the window) [m] and the share of
    instants that are not, of the instants in `sq` / `tracked` / `w` (same shapes)."""
    seen = float(np.sum(w * tracked))
    e_tracked = float(np.sqrt(float(np.sum(w * tracked * sq)) / seen)) if seen > 0 else None
    return {"E_tracked": e_tracked, "missed_share": 1.0 - seen / float(np.sum(w))}


def tracked_summary(hard: Any, weight: np.ndarray, miss_penalty_m2: float) -> dict[str, Any]:
    """The "tracked" question's pieces at one hard evaluation: E over the tracked instants [m],
    the missed share and J [m^2] (with the objective's one pseudo-instant of zero error)."""
    sq = np.asarray(hard.sq_instant, np.float64)
    tracked = np.asarray(hard.coverage, np.float64)[..., 1]
    w = np.broadcast_to(np.asarray(weight, np.float64)[:, None], sq.shape)
    part = _tracked_part(sq, tracked, w)
    seen = float(np.sum(w * tracked))
    error = float(np.sum(w * tracked * sq))
    return part | {"J_m2": error / (1.0 + seen) + miss_penalty_m2 * part["missed_share"],
                   "miss_penalty_m2": miss_penalty_m2}


__all__ = ["COVERAGE_PARTS", "breakdown", "tracked_summary"]
