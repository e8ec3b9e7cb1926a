"""Map a PyTorch CS-LSTM `state_dict` onto the NNX network and back; infer the variant.

PyTorch Linear weights are [out, in] (ours [in, out]); LSTM weights [4H, in] (ours [in, 4H]);
Conv2d kernels [out, in, kh, kw] (ours HWIO [kh, kw, in, out]).
"""

from __future__ import annotations

import numpy as np
from flax import nnx

from diffsense.predictors._model import CSLSTM, model_from_params, param_shapes
from diffsense.runtime import InputError

_LINEARS = ("ip_emb", "dyn_emb", "op", "op_lat", "op_lon")
_LSTMS = ("enc_lstm", "dec_lstm")
_CONVS = ("soc_conv", "conv_3x1")


def _torch_to_ours(sd: dict[str, np.ndarray]) -> dict:
    tree: dict = {}
    for name in _LINEARS:
        tree[name] = {"weight": sd[f"{name}.weight"].T, "bias": sd[f"{name}.bias"]}
    for name in _LSTMS:
        tree[name] = {
            "w_ih": sd[f"{name}.weight_ih_l0"].T,
            "w_hh": sd[f"{name}.weight_hh_l0"].T,
            "b_ih": sd[f"{name}.bias_ih_l0"],
            "b_hh": sd[f"{name}.bias_hh_l0"],
        }
    for name in _CONVS:
        tree[name] = {"kernel": sd[f"{name}.weight"].transpose(2, 3, 1, 0), "bias": sd[f"{name}.bias"]}
    return tree


def state_dict_from_model(model: CSLSTM) -> dict[str, np.ndarray]:
    """The PyTorch `state_dict` (float32 numpy, torch layout) of a network."""
    pure = nnx.to_pure_dict(nnx.state(model, nnx.Param))
    return _ours_to_torch({k: {kk: np.asarray(vv) for kk, vv in v.items()} for k, v in pure.items()})


def _ours_to_torch(p: dict) -> dict[str, np.ndarray]:
    sd = {}
    for name in _LINEARS:
        sd[f"{name}.weight"], sd[f"{name}.bias"] = p[name]["weight"].T, p[name]["bias"]
    for name in _LSTMS:
        sd[f"{name}.weight_ih_l0"] = p[name]["w_ih"].T
        sd[f"{name}.weight_hh_l0"] = p[name]["w_hh"].T
        sd[f"{name}.bias_ih_l0"], sd[f"{name}.bias_hh_l0"] = p[name]["b_ih"], p[name]["b_hh"]
    for name in _CONVS:
        sd[f"{name}.weight"] = p[name]["kernel"].transpose(3, 2, 0, 1)
        sd[f"{name}.bias"] = p[name]["bias"]
    return {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in sd.items()}


def model_from_state_dict(sd: dict[str, np.ndarray], source: str = "checkpoint") -> CSLSTM:
    """Build the network from a PyTorch `state_dict`; the variant comes from dec_lstm's input size.

    Any missing or unexpected key, or a shape other than the reference's, is one InputError.
    """
    n_in = sd.get("dec_lstm.weight_ih_l0", np.zeros((0, 0))).shape[-1]
    if n_in not in (112, 117):
        raise InputError(
            f"{source}: dec_lstm.weight_ih_l0 has {n_in} input columns; CS-LSTM has 112 "
            "(single-mode) or 117 (manoeuvre)"
        )
    maneuvers = n_in == 117
    shapes = param_shapes(maneuvers)
    expected = _ours_to_torch({k: {kk: np.zeros(vv) for kk, vv in v.items()} for k, v in shapes.items()})
    missing = sorted(set(expected) - set(sd))
    unexpected = sorted(set(sd) - set(expected))
    if missing or unexpected:
        what = f"missing key {missing[0]}" if missing else f"unexpected key {unexpected[0]}"
        raise InputError(f"{source}: not a CS-LSTM state_dict ({what})")
    for key, ref in expected.items():
        if sd[key].shape != ref.shape:
            raise InputError(f"{source}: {key} has shape {sd[key].shape}, expected {ref.shape}")
        if not np.all(np.isfinite(sd[key])):
            raise InputError(f"{source}: {key} contains NaN or inf")
    return model_from_params(maneuvers, _torch_to_ours({k: np.asarray(v, np.float32) for k, v in sd.items()}))
