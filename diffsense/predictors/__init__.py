"""Trajectory predictors: the `Predictor` protocol, its `InputSpec`, and the CS-LSTM.

A predictor is any pytree with a `spec` (`InputSpec`: history and future length, rate, social
grid) and a pure call `predictor(inputs) -> [B, F, 2]`; `tracks` builds its inputs to the spec.
The shipped implementation is the CS-LSTM (Deo & Trivedi 2018) in Flax NNX, SI at its boundary.

Entry points: `load_predictor` (shipped weights, a project `.msgpack`, or a published PyTorch
checkpoint read without torch), `predict_mean` (compact neighbours) and `predict_mean_dense`
(the 39-slot grid), both pure and jit/grad-able (reverse mode; `jax.jvp` inside `forward_mode()`); `with_compute_dtype` runs any predictor at its
own float precision inside an objective of another (float32 inside a float64 E(r)). `si_to_model` / `model_to_si` are the only unit
and axis conversion. CLI: `python -m diffsense.predictors {parity,card}`.
"""

from diffsense.predictors._api import (
    CSLSTMPredictor,
    init_predictor,
    load_predictor,
    predict_mean,
    predict_mean_dense,
    predict_model_frame,
    select_mean,
)
from diffsense.predictors._cast import COMPUTE_DTYPES, CastPredictor, with_compute_dtype
from diffsense.predictors._checkpoint import read_state_dict
from diffsense.predictors._convert import model_from_state_dict, state_dict_from_model
from diffsense.predictors._frame import model_to_si, si_to_model
from diffsense.predictors._lstm_forward import forward_mode
from diffsense.predictors._model import (
    CSLSTM,
    FUT_LEN,
    HIST_LEN,
    N_LAT,
    N_LON,
    N_SLOTS,
    Prediction,
    new_model,
    output_activation,
)
from diffsense.predictors._parity import reference_forward, reference_to_compact
from diffsense.predictors._protocol import Predictor
from diffsense.predictors._weights import (
    DEFAULT_WEIGHTS,
    load_weights,
    read_card,
    save_weights,
)
from diffsense.tracks import CSLSTM_SPEC, M_PER_FT, InputSpec, PredictorInputs

__all__ = [
    "COMPUTE_DTYPES",
    "CastPredictor",
    "CSLSTM_SPEC",
    "N_LAT",
    "N_LON",
    "new_model",
    "InputSpec",
    "Predictor",
    "PredictorInputs",
    "CSLSTM",
    "DEFAULT_WEIGHTS",
    "forward_mode",
    "FUT_LEN",
    "HIST_LEN",
    "M_PER_FT",
    "N_SLOTS",
    "Prediction",
    "CSLSTMPredictor",
    "init_predictor",
    "load_predictor",
    "load_weights",
    "model_from_state_dict",
    "model_to_si",
    "output_activation",
    "predict_mean",
    "predict_mean_dense",
    "predict_model_frame",
    "read_card",
    "read_state_dict",
    "reference_forward",
    "reference_to_compact",
    "save_weights",
    "select_mean",
    "si_to_model",
    "state_dict_from_model",
    "with_compute_dtype",
]
