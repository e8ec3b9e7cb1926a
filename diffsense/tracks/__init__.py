"""Tracks: from detections to what a predictor eats (histories, fill policies, social grid).

Every function takes the predictor's `InputSpec` (default: the CS-LSTM's), the one place the
history length, rate and grid are written.
"""

from diffsense.tracks._fill import FILL_POLICIES, FillPolicy, fill_window
from diffsense.tracks._inputs import (
    build_inputs,
    flatten_instants,
    grid_slots,
    ground_truth_detections,
    prediction_frames,
    true_future,
)
from diffsense.tracks._spec import CSLSTM_SPEC, M_PER_FT, InputSpec, PredictorInputs

__all__ = [
    "CSLSTM_SPEC", "FILL_POLICIES", "FillPolicy", "InputSpec", "M_PER_FT", "PredictorInputs", "build_inputs", "fill_window",
    "flatten_instants", "grid_slots", "ground_truth_detections", "prediction_frames", "true_future",
]
