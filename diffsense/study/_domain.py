"""The predictor's domain: is a scenario one the predictor can forecast from perfect histories?

E (Eq. 12) compares the prediction from sensor histories with the prediction from ground-truth
histories. If the latter is already far from the true future, the scenario lies outside what the
predictor learnt (e.g. speeds its training traffic never reached), and E there says little about
the sensor. Rule: a scenario is outside the domain when, at any whole-second horizon h, the RMSE of
its ground-truth-input prediction against the true future exceeds DOMAIN_FACTOR x the predictor's
validation RMSE at h (its model card's; the published figures for the NGSIM checkpoints).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from diffsense.runtime import to_host

DOMAIN_FACTOR = 2.0


def domain_check(E: Any, validation_rmse_m: tuple[float, ...] | None) -> dict[str, Any]:
    """{"factor", "validation_rmse_m", "scenarios": {name: {"rmse_gt_m": [per s], "inside": bool}},
    "outside": [names]}; without validation figures every scenario is reported, none judged."""
    gt, true, weight, scenario = to_host((E.data.gt_pred, E.data.true_fut, E.data.weight, E.data.scenario))
    gt, true, weight = (np.asarray(a, np.float64) for a in (gt, true, weight))
    per_s = int(round(E.spec.rate_hz))
    steps = [per_s * k - 1 for k in range(1, E.spec.future_points // per_s + 1)]  # 1 s, 2 s, ...
    sq = np.sum((gt - true) ** 2, axis=-1)  # [N, I, F]
    out: dict[str, Any] = {"factor": DOMAIN_FACTOR, "validation_rmse_m": validation_rmse_m, "scenarios": {}, "outside": []}
    for s, name in enumerate(E.scenario_names):
        w = weight * (scenario == s)
        rmse = [float(np.sqrt(np.sum(w[:, None] * sq[:, :, h]) / (np.sum(w) * sq.shape[1]))) for h in steps]
        inside = None
        if validation_rmse_m is not None:
            inside = all(r <= DOMAIN_FACTOR * v for r, v in zip(rmse, validation_rmse_m))
            if not inside:
                out["outside"].append(name)
        out["scenarios"][name] = {"rmse_gt_m": rmse, "inside": inside}
    return out


def domain_note(check: dict[str, Any]) -> str | None:
    """The warning for scenarios outside the domain, or None."""
    if not check["outside"]:
        return None
    worst = ", ".join(f"{n} ({check['scenarios'][n]['rmse_gt_m'][-1]:.1f} m at {len(check['scenarios'][n]['rmse_gt_m'])} s)"
                      for n in check["outside"])
    return (f"outside the predictor's domain: {worst}: even from ground-truth histories its prediction is more "
            f"than {check['factor']:g}x its validation RMSE off the true future, so E there says little about the sensor")
