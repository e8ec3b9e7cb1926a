"""CS-LSTM (Deo & Trivedi 2018) in Flax NNX, in the model frame of the NGSIM checkpoints.

Model frame: every (x, y) is (lateral, positive to the right; longitudinal, forward) in feet,
relative to the target at the prediction instant; 5 Hz, 16 history and 25 future points. The SI
road frame of the rest of the project is converted in `_frame.py`, nowhere else.

Social grid: 39 slots, id = lane * 13 + cell (lane 0 left, 1 own, 2 right; cell 0 rearmost,
15 ft each). A neighbour's history encoding (64) times its occupancy weight in [0, 1] fills its
slot; empty slots are zero, so occupancy 0 is exactly an absent neighbour. The grid goes through
conv 3x3 (no padding) -> LeakyReLU -> conv 3x1 -> LeakyReLU -> max-pool (2, 1) with padding
(1, 0) -> 16 x 5 = 80 features, concatenated with the target's dynamics encoding (32) into the
decoder input (112, + 3 + 2 manoeuvre one-hots in the manoeuvre variant), repeated 25 times into
an LSTM 128 and Linear 128 -> 5: [mu_x, mu_y, exp(.), exp(.), tanh(.)] (the two exp outputs are
inverse standard deviations).
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
from flax import nnx
from jaxtyping import Array, Float, Int

from diffsense.predictors._layers import LSTM, FullWidthConv, Linear
from diffsense.predictors._lstm import leaky_relu

HIST_LEN = 16
FUT_LEN = 25
N_LANES = 3
N_CELLS = 13
N_SLOTS = N_LANES * N_CELLS
N_LAT = 3  # keep, left, right
N_LON = 2  # normal, braking
N_MODES = N_LAT * N_LON
ENC_SIZE = 64
SOC_SIZE = 80  # 16 channels x 5 pooled cells
DYN_SIZE = 32
DEC_SIZE = 128


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Prediction:
    """What the network returns, in the model frame (feet, lateral right).

    fut: [B, K, 25, 5] (mu_lat, mu_lon, 1/sigma_lat, 1/sigma_lon, rho) per mode; K = 1 for the
      single-mode variant, 6 for the manoeuvre variant, lon-major (mode = lon * 3 + lat).
    mode_prob: [B, K] probability of each mode (ones for the single-mode variant).
    lat_prob: [B, 3] (keep, left, right) and lon_prob: [B, 2] (normal, braking); manoeuvre
      variant only, else None.
    """

    fut: Float[Array, "B K 25 5"]
    mode_prob: Float[Array, "B K"]
    lat_prob: Float[Array, "B 3"] | None = None
    lon_prob: Float[Array, "B 2"] | None = None


def output_activation(raw: Float[Array, "... 5"]) -> Float[Array, "... 5"]:
    """The reference's outputActivation: [mu_x, mu_y, exp, exp, tanh]."""
    return jnp.concatenate(
        [raw[..., :2], jnp.exp(raw[..., 2:4]), jnp.tanh(raw[..., 4:5])], axis=-1
    )


def _max_pool_2x1_pad1(x: Float[Array, "B 9 C"]) -> Float[Array, "B 5 C"]:
    """MaxPool2d((2, 1), padding=(1, 0)) along the cell axis: windows (-1, 0), (1, 2), ..."""
    return jnp.concatenate([x[:, :1], jnp.maximum(x[:, 1::2], x[:, 2::2])], axis=1)


class CSLSTM(nnx.Module):
    """Convolutional social LSTM; `maneuvers` selects the manoeuvre-based decoder (3 x 2)."""

    def __init__(self, maneuvers: bool = False, *, rngs: nnx.Rngs):
        self.maneuvers = maneuvers
        self.ip_emb = Linear(2, 32, rngs=rngs)
        self.enc_lstm = LSTM(32, ENC_SIZE, rngs=rngs)
        self.dyn_emb = Linear(ENC_SIZE, DYN_SIZE, rngs=rngs)
        # Convolution kernels in HWIO layout: H = cell (3), W = lane (3 | 1).
        self.soc_conv = FullWidthConv(3, 3, ENC_SIZE, 64, rngs=rngs)
        self.conv_3x1 = FullWidthConv(3, 1, 64, 16, rngs=rngs)
        n_dec_in = SOC_SIZE + DYN_SIZE + (N_LAT + N_LON if maneuvers else 0)
        self.dec_lstm = LSTM(n_dec_in, DEC_SIZE, rngs=rngs)
        self.op = Linear(DEC_SIZE, 5, rngs=rngs)
        # Present in both published variants (the reference always builds them).
        self.op_lat = Linear(SOC_SIZE + DYN_SIZE, N_LAT, rngs=rngs)
        self.op_lon = Linear(SOC_SIZE + DYN_SIZE, N_LON, rngs=rngs)

    # -- encoders -------------------------------------------------------------------------------
    def encode_tracks(self, xy: Float[Array, "*N 16 2"]) -> Float[Array, "*N 64"]:
        """Final LSTM hidden state of each history (time on axis -2)."""
        lead = xy.shape[:-2]
        seq = jnp.moveaxis(xy.reshape((-1, HIST_LEN, 2)), 1, 0)  # [T, N, 2]
        return self.enc_lstm.final(seq, embedding=self.ip_emb).reshape(lead + (ENC_SIZE,))

    def social(self, grid: Float[Array, "B 39 64"]) -> Float[Array, "B 80"]:
        """Convolutional social pooling of the filled grid (flattened channel-major like torch)."""
        b = grid.shape[0]
        g = grid.reshape(b, N_LANES, N_CELLS, ENC_SIZE).transpose(0, 2, 1, 3)  # [B, cell, lane, C]
        g = leaky_relu(self.soc_conv(g))  # [B, 11, 64]
        g = leaky_relu(self.conv_3x1(g[:, :, None, :]))  # [B, 9, 16]
        pooled = _max_pool_2x1_pad1(g)  # [B, 5, 16]
        return pooled.transpose(0, 2, 1).reshape(b, SOC_SIZE)

    def context(
        self, hist_enc: Float[Array, "B 64"], grid: Float[Array, "B 39 64"]
    ) -> Float[Array, "B 112"]:
        """Decoder context: concat(social 80, dynamics 32), the reference's `enc`."""
        dyn = leaky_relu(self.dyn_emb(hist_enc))
        return jnp.concatenate([self.social(grid), dyn], axis=-1)

    # -- decoders -------------------------------------------------------------------------------
    def decode_raw(self, enc: Float[Array, "N D"]) -> Float[Array, "N 25 5"]:
        """Trajectory before the output activation; `enc` includes any manoeuvre one-hots."""
        hs = self.dec_lstm.repeated(enc, FUT_LEN)
        return jnp.moveaxis(self.op(hs), 0, 1)

    def maneuver_onehots(self, dtype) -> Float[Array, "6 5"]:
        """(lat one-hot, lon one-hot) of the 6 modes, lon-major: mode = lon * 3 + lat."""
        lat = jnp.tile(jnp.eye(N_LAT, dtype=dtype), (N_LON, 1))
        lon = jnp.repeat(jnp.eye(N_LON, dtype=dtype), N_LAT, axis=0)
        return jnp.concatenate([lat, lon], axis=-1)

    def heads(self, enc: Float[Array, "B 112"]) -> Prediction:
        """Evaluation-mode outputs from the context (all modes for the manoeuvre variant)."""
        b = enc.shape[0]
        if not self.maneuvers:
            fut = output_activation(self.decode_raw(enc))[:, None]
            return Prediction(fut=fut, mode_prob=jnp.ones((b, 1), enc.dtype))
        lat_prob = jax.nn.softmax(self.op_lat(enc), axis=-1)
        lon_prob = jax.nn.softmax(self.op_lon(enc), axis=-1)
        onehots = self.maneuver_onehots(enc.dtype)
        enc6 = jnp.concatenate(
            [jnp.repeat(enc[:, None], N_MODES, axis=1), jnp.broadcast_to(onehots, (b,) + onehots.shape)],
            axis=-1,
        )
        raw = self.decode_raw(enc6.reshape(b * N_MODES, -1)).reshape(b, N_MODES, FUT_LEN, 5)
        mode_prob = (lon_prob[:, :, None] * lat_prob[:, None, :]).reshape(b, N_MODES)
        return Prediction(output_activation(raw), mode_prob, lat_prob, lon_prob)

    def mean_from_context(self, enc: Float[Array, "B 112"], mode: str = "most_probable") -> Float[Array, "B 25 2"]:
        """The mean trajectory (model frame) without decoding modes nobody asked for.

        Single-mode: the one trajectory. Manoeuvre, "most_probable": the reference evaluation's
        choice (argmax of the lateral and of the longitudinal probabilities), decoded alone with
        its one-hots, which is the same as decoding all 6 and picking one. "weighted": the
        probability-weighted mean of all 6.
        """
        if not self.maneuvers:
            return self.decode_raw(enc)[..., :2]
        if mode == "weighted":
            pred = self.heads(enc)
            return jnp.einsum("bk,bktc->btc", pred.mode_prob, pred.fut[..., :2])
        if mode != "most_probable":
            raise ValueError(f"mode must be 'most_probable' or 'weighted', got {mode!r}")
        lat = jnp.argmax(jax.nn.softmax(self.op_lat(enc), axis=-1), axis=-1)
        lon = jnp.argmax(jax.nn.softmax(self.op_lon(enc), axis=-1), axis=-1)
        onehots = [jax.nn.one_hot(lat, N_LAT, dtype=enc.dtype), jax.nn.one_hot(lon, N_LON, dtype=enc.dtype)]
        return self.decode_raw(jnp.concatenate([enc, *onehots], axis=-1))[..., :2]

    # -- the two entry points ---------------------------------------------------------------------
    def __call__(
        self,
        hist: Float[Array, "B 16 2"],
        nbrs: Float[Array, "B 39 16 2"],
        occupancy: Float[Array, "B 39"],
    ) -> Prediction:
        """Dense input: every grid slot has a history; occupancy in [0, 1] scales its encoding."""
        return self.heads(self.context_dense(hist, nbrs, occupancy))

    def context_dense(
        self,
        hist: Float[Array, "B 16 2"],
        nbrs: Float[Array, "B 39 16 2"],
        occupancy: Float[Array, "B 39"],
    ) -> Float[Array, "B 112"]:
        """The decoder context from dense input (see `__call__`)."""
        b = hist.shape[0]
        enc = self.encode_tracks(jnp.concatenate([hist[:, None], nbrs], axis=1))
        grid = occupancy[..., None] * enc[:, 1:]
        return self.context(enc[:, 0], grid.reshape(b, N_SLOTS, ENC_SIZE))

    def compact(
        self,
        hist: Float[Array, "B 16 2"],
        nbr_hist: Float[Array, "B N 16 2"],
        nbr_slot: Int[Array, "B N"],
        nbr_weight: Float[Array, "B N"],
    ) -> Prediction:
        """Compact input: only the N listed neighbours are encoded, then scattered to their slots.

        Slots outside 0..38 are ignored (padding); two neighbours in one slot add up.
        """
        return self.heads(self.context_compact(hist, nbr_hist, nbr_slot, nbr_weight))

    def context_compact(
        self,
        hist: Float[Array, "B 16 2"],
        nbr_hist: Float[Array, "B N 16 2"],
        nbr_slot: Int[Array, "B N"],
        nbr_weight: Float[Array, "B N"],
    ) -> Float[Array, "B 112"]:
        """The decoder context from compact input (see `compact`)."""
        b, n = nbr_slot.shape
        enc = self.encode_tracks(jnp.concatenate([hist[:, None], nbr_hist], axis=1))
        valid = (nbr_slot >= 0) & (nbr_slot < N_SLOTS)
        slot = jnp.where(valid, nbr_slot, N_SLOTS)  # one spare row takes what is dropped
        rows = jnp.broadcast_to(jnp.arange(b)[:, None], (b, n))
        grid = jnp.zeros((b, N_SLOTS + 1, ENC_SIZE), enc.dtype)
        grid = grid.at[rows, slot].add(nbr_weight[..., None].astype(enc.dtype) * enc[:, 1:])
        return self.context(enc[:, 0], grid[:, :N_SLOTS])


@functools.lru_cache(maxsize=2)
def _init_fn(maneuvers: bool):
    """Compiled once per variant: the initial parameters as a function of the seed."""
    return jax.jit(lambda key: nnx.split(CSLSTM(maneuvers, rngs=nnx.Rngs(params=key)))[1])


def new_model(maneuvers: bool, seed: int) -> CSLSTM:
    """A freshly initialised network (PyTorch's default init), built in one compiled call."""
    graphdef, _ = nnx.split(nnx.eval_shape(lambda: CSLSTM(maneuvers, rngs=nnx.Rngs(0))))
    return nnx.merge(graphdef, _init_fn(maneuvers)(jax.random.key(seed)))


@functools.lru_cache(maxsize=2)
def _abstract(maneuvers: bool):
    """(graphdef, state of shapes) of the network, traced without any arithmetic, once per
    variant (the trace is a JAX trace a warm run would otherwise pay at every weight load)."""
    return nnx.split(nnx.eval_shape(lambda: CSLSTM(maneuvers, rngs=nnx.Rngs(0))))


def model_from_params(maneuvers: bool, params: dict) -> CSLSTM:
    """The network with the given parameter arrays (a pure dict shaped like `param_shapes`)."""
    graphdef, shapes = _abstract(maneuvers)
    state = jax.tree.map(lambda leaf: leaf, shapes)  # a copy: the cached shapes stay as they are
    nnx.replace_by_pure_dict(state, jax.tree.map(jax.device_put, params))  # no program per array
    return nnx.merge(graphdef, state)


def param_shapes(maneuvers: bool) -> dict:
    """{group: {name: shape}} of the network's parameters, computed without any arithmetic."""
    return {k: dict(v) for k, v in _shape_table(maneuvers)}


@functools.lru_cache(maxsize=2)
def _shape_table(maneuvers: bool) -> tuple:
    _, state = _abstract(maneuvers)
    return tuple((k, tuple((kk, tuple(vv.shape)) for kk, vv in v.items())) for k, v in nnx.to_pure_dict(state).items())
