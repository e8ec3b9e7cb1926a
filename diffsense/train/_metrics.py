"""Validation metrics in SI: RMSE per horizon second, and the constant-velocity baseline."""

from __future__ import annotations

import numpy as np

DT_S = 0.2  # 5 Hz
SECOND_INDEX = np.array([4, 9, 14, 19, 24])  # future points at 1, 2, 3, 4, 5 s


def rmse_per_second(pred_m: np.ndarray, fut_m: np.ndarray) -> np.ndarray:
    """[5]: sqrt(mean over samples of the squared position error) at 1..5 s [m]."""
    err2 = np.sum((np.asarray(pred_m, np.float64) - np.asarray(fut_m, np.float64)) ** 2, axis=-1)
    return np.sqrt(np.mean(err2[:, SECOND_INDEX], axis=0))


def rmse_per_second_by_axis(pred_m: np.ndarray, fut_m: np.ndarray) -> dict[str, list[float]]:
    """{"lon": [5], "lat": [5]}: the RMSE at 1..5 s of each road-frame component alone [m]
    (their squares add up to `rmse_per_second`'s)."""
    err2 = (np.asarray(pred_m, np.float64) - np.asarray(fut_m, np.float64)) ** 2
    per_axis = np.sqrt(np.mean(err2[:, SECOND_INDEX], axis=0))  # [5, 2]
    return {"lon": [round(float(v), 4) for v in per_axis[:, 0]],
            "lat": [round(float(v), 4) for v in per_axis[:, 1]]}


def constant_velocity_m(hist_m: np.ndarray, points: int) -> np.ndarray:
    """[S, 25, 2] future of a constant-velocity model: the mean velocity of the last `points`
    history points, extrapolated from the last one (at the prediction instant)."""
    hist_m = np.asarray(hist_m, np.float64)
    velocity = (hist_m[:, -1] - hist_m[:, -points]) / ((points - 1) * DT_S)  # [S, 2] m/s
    t = DT_S * np.arange(1, 26)[:, None]
    return hist_m[:, -1][:, None, :] + velocity[:, None, :] * t
