"""The predictor's functional entry points, in SI at the boundary.

`load_predictor` gives a `CSLSTMPredictor` pytree (graphdef static, parameters as leaves), so every
function here is pure and can be passed through plain `jax.jit` / `jax.grad` / `jax.vmap`; the
network is rebuilt inside with `nnx.merge` (no nnx.jit overhead in hot loops). Parameters are
cast to the dtype of the histories: float32 in, float32 out; float64 in, float64 out.

Inputs (SI road frame of the target at the prediction instant, last axis (lon_m, lat_m) =
(forward, left), 5 Hz, oldest first, the last point at the prediction instant):
  hist_m [B, 16, 2]; compact neighbours nbr_hist_m [B, N, 16, 2], nbr_slot [B, N] int
  (lane * 13 + cell, lane 0 left; slots outside 0..38 are padding), nbr_weight [B, N] in [0, 1];
  or dense neighbours nbrs_m [B, 39, 16, 2] with occupancy [B, 39] in [0, 1].
Output: future mean [B, 25, 2] (0.2 .. 5 s) in the same SI frame.

Manoeuvre variant: `mode="most_probable"` (the default) returns the trajectory of the most
probable lateral and the most probable longitudinal class, as the reference evaluation does
(its gradient flows through that trajectory; the choice itself is piecewise constant);
`mode="weighted"` returns the probability-weighted mean of the 6 trajectories (smooth in the
inputs). The single-mode variant has one trajectory and ignores `mode`. Under jit, `mode` is a
static argument: `jax.jit(predict_mean, static_argnames="mode")`.

Differentiation is reverse mode (`jax.grad`, `jax.vjp`) by default: the LSTM has a hand-written
backward (`jax.custom_vjp`). Traced inside `diffsense.predictors.forward_mode()`, it has a
forward-mode rule instead (`jax.jvp`; reverse mode is then unavailable), which
`diffsense.metrics.value_and_grad` uses for a one-parameter objective.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import ClassVar, Literal

import jax
import jax.numpy as jnp
from flax import nnx
from jaxtyping import Array, Float, Int

from diffsense.predictors._checkpoint import read_state_dict
from diffsense.predictors._convert import model_from_state_dict
from diffsense.predictors._frame import model_to_si, si_to_model
from diffsense.predictors._model import CSLSTM, N_LAT, Prediction, new_model
from diffsense.predictors._weights import DEFAULT_WEIGHTS, load_weights, read_card
from diffsense.runtime import InputError
from diffsense.tracks import CSLSTM_SPEC, InputSpec, PredictorInputs

Mode = Literal["most_probable", "weighted"]


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class CSLSTMPredictor:
    """A CS-LSTM as data: `graphdef` (static structure) and `state` (its parameter arrays).

    Implements `Predictor`: `predictor(inputs)` is `predict_mean` on the inputs (the most
    probable manoeuvre). `maneuvers` is True for the manoeuvre-based variant (6 modes), False
    for single-mode. `product_dtype` "bfloat16" runs the LSTMs' matrix products on bfloat16
    operands into float32 sums (`with_compute_dtype(predictor, "bfloat16")`); None keeps every
    product in the inputs' precision.
    """

    spec: ClassVar[InputSpec] = CSLSTM_SPEC

    state: nnx.State
    graphdef: nnx.GraphDef = dataclasses.field(metadata=dict(static=True))
    maneuvers: bool = dataclasses.field(metadata=dict(static=True))
    validation_rmse_m: tuple[float, ...] | None = dataclasses.field(default=None, metadata=dict(static=True))
    product_dtype: str | None = dataclasses.field(default=None, metadata=dict(static=True))

    @classmethod
    def from_model(cls, model: CSLSTM, validation_rmse_m: tuple[float, ...] | None = None) -> CSLSTMPredictor:
        """`validation_rmse_m`: the RMSE [m] at 1, 2, ... s on the data the weights were
        validated on (the model card's), or None when unknown."""
        graphdef, state = nnx.split(model)
        return cls(state=state, graphdef=graphdef, maneuvers=bool(model.maneuvers),
                   validation_rmse_m=None if validation_rmse_m is None else tuple(map(float, validation_rmse_m)))

    def __call__(self, inputs: PredictorInputs) -> Float[Array, "B 25 2"]:
        """Future mean [B, 25, 2] in SI (the `Predictor` protocol)."""
        return predict_mean(self, inputs.hist, inputs.nbr_hist, inputs.nbr_slot, inputs.nbr_weight)

    def model(self, dtype=None) -> CSLSTM:
        """The network (parameters cast to `dtype` when given, then the LSTMs' matrices to
        `product_dtype` when set); usable inside jit."""
        state = self.state
        if dtype is not None:
            state = jax.tree.map(lambda p: p.astype(dtype), state)
        if self.product_dtype is not None:
            state = jax.tree_util.tree_map_with_path(
                lambda path, p: p.astype(self.product_dtype) if _is_lstm_matrix(path) else p, state)
        return nnx.merge(self.graphdef, state)


def _is_lstm_matrix(path) -> bool:
    """Whether a state leaf's key path names an LSTM's w_ih or w_hh (the products' weights)."""
    return any(getattr(k, "key", None) in ("w_ih", "w_hh") for k in path)


def init_predictor(maneuvers: bool = False, seed: int = 0) -> CSLSTMPredictor:
    """An untrained predictor (PyTorch's default initialisation): for tests and training only."""
    return CSLSTMPredictor.from_model(new_model(maneuvers, seed))


def load_predictor(path: str | Path | None = None) -> CSLSTMPredictor:
    """The default shipped predictor (`path=None`), a `.msgpack` weight file of this project, or a
    published PyTorch checkpoint (any other file; read without torch, variant from the shapes)."""
    if path is None:
        if not DEFAULT_WEIGHTS.is_file():
            raise InputError(
                f"no shipped weights at {DEFAULT_WEIGHTS}: train them with `python -m diffsense.train "
                "--config configs/train/default.toml` or pass a checkpoint path"
            )
        return CSLSTMPredictor.from_model(load_weights(DEFAULT_WEIGHTS), _card_rmse(DEFAULT_WEIGHTS))
    path = Path(path)
    if path.suffix == ".msgpack":
        return CSLSTMPredictor.from_model(load_weights(path), _card_rmse(path))
    return CSLSTMPredictor.from_model(model_from_state_dict(read_state_dict(path), str(path)), PUBLISHED_NGSIM_RMSE_M)


# Published NGSIM test RMSE of CS-LSTM at 1..5 s (Deo & Trivedi 2018, single-mode; the manoeuvre
# variant is close): the validation figures of the published PyTorch checkpoints.
PUBLISHED_NGSIM_RMSE_M = (0.61, 1.27, 2.09, 3.10, 4.37)


def _card_rmse(weights_path: Path) -> tuple[float, ...] | None:
    """The validation RMSE at 1..5 s of a weight file's model card (None without a card)."""
    try:
        return tuple(float(v) for v in read_card(weights_path)["validation"]["rmse_m"]["cslstm"])
    except (InputError, KeyError, TypeError, ValueError):
        return None


def predict_model_frame(
    predictor: CSLSTMPredictor,
    hist: Float[Array, "B 16 2"],
    nbr_hist: Float[Array, "B N 16 2"],
    nbr_slot: Int[Array, "B N"],
    nbr_weight: Float[Array, "B N"],
) -> Prediction:
    """All network outputs (every mode, inverse sigmas, rho, class probabilities), compact input
    in the MODEL frame (feet, lateral right): for parity checks and training, not for the pipeline."""
    return predictor.model(hist.dtype).compact(hist, nbr_hist, nbr_slot, nbr_weight)


def select_mean(pred: Prediction, mode: Mode = "most_probable") -> Float[Array, "B 25 2"]:
    """The mean trajectory [B, 25, 2] of a prediction (model frame), chosen by `mode` (see above)."""
    mu = pred.fut[..., :2]  # [B, K, 25, 2]
    if mu.shape[1] == 1:
        return mu[:, 0]
    if mode == "weighted":
        return jnp.einsum("bk,bktc->btc", pred.mode_prob, mu)
    if mode != "most_probable":
        raise ValueError(f"mode must be 'most_probable' or 'weighted', got {mode!r}")
    idx = jnp.argmax(pred.lon_prob, axis=-1) * N_LAT + jnp.argmax(pred.lat_prob, axis=-1)
    return jnp.take_along_axis(mu, idx[:, None, None, None], axis=1)[:, 0]


def predict_mean(
    predictor: CSLSTMPredictor,
    hist_m: Float[Array, "B 16 2"],
    nbr_hist_m: Float[Array, "B N 16 2"],
    nbr_slot: Int[Array, "B N"],
    nbr_weight: Float[Array, "B N"],
    mode: Mode = "most_probable",
) -> Float[Array, "B 25 2"]:
    """Future mean [B, 25, 2] in SI from compact neighbours (only the N listed are encoded)."""
    model = predictor.model(hist_m.dtype)
    enc = model.context_compact(si_to_model(hist_m), si_to_model(nbr_hist_m), nbr_slot, nbr_weight)
    return model_to_si(model.mean_from_context(enc, mode))


def predict_mean_dense(
    predictor: CSLSTMPredictor,
    hist_m: Float[Array, "B 16 2"],
    nbrs_m: Float[Array, "B 39 16 2"],
    occupancy: Float[Array, "B 39"],
    mode: Mode = "most_probable",
) -> Float[Array, "B 25 2"]:
    """Future mean [B, 25, 2] in SI from the dense grid (all 39 slots encoded)."""
    model = predictor.model(hist_m.dtype)
    enc = model.context_dense(si_to_model(hist_m), si_to_model(nbrs_m), occupancy.astype(hist_m.dtype))
    return model_to_si(model.mean_from_context(enc, mode))
