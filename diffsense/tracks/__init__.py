"""Tracks: from detections to predictor inputs (histories, fill policies, social grid)."""

from diffsense.tracks._fill import FILL_POLICIES, FillPolicy, fill_window
from diffsense.tracks._inputs import (
    FRAMES_PER_POINT,
    FUTURE_FRAMES,
    FUTURE_POINTS,
    GRID_CELL_M,
    GRID_CELLS,
    GRID_LANES,
    GRID_SIZE,
    HISTORY_FRAMES,
    HISTORY_POINTS,
    PredictorInputs,
    build_inputs,
    flatten_instants,
    grid_slots,
    ground_truth_detections,
    prediction_frames,
    true_future,
)

__all__ = [
    "FILL_POLICIES", "FillPolicy", "fill_window",
    "FRAMES_PER_POINT", "FUTURE_FRAMES", "FUTURE_POINTS", "GRID_CELL_M", "GRID_CELLS",
    "GRID_LANES", "GRID_SIZE", "HISTORY_FRAMES", "HISTORY_POINTS", "PredictorInputs",
    "build_inputs", "flatten_instants", "grid_slots", "ground_truth_detections",
    "prediction_frames", "true_future",
]
