"""The project's own weight files: msgpack parameters (flax.serialization) plus a JSON model card.

File layout: {"format": "diffsense-cslstm", "version": 1, "maneuvers": bool, "params": {...}},
params being the network's pure dict (float32, model frame: feet, lateral right).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from flax import nnx, serialization

from diffsense import runtime
from diffsense.predictors._model import CSLSTM, model_from_params, param_shapes
from diffsense.runtime import InputError

FORMAT = "diffsense-cslstm"
VERSION = 1
WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"
DEFAULT_WEIGHTS = WEIGHTS_DIR / "cslstm.msgpack"


def card_path(weights_path: str | Path) -> Path:
    """The model card that belongs to a weight file (same name, .json)."""
    return Path(weights_path).with_suffix(".json")


def weights_to_bytes(model: CSLSTM) -> bytes:
    params = nnx.to_pure_dict(nnx.state(model, nnx.Param))
    params = {k: {kk: np.asarray(vv, np.float32) for kk, vv in v.items()} for k, v in params.items()}
    return serialization.msgpack_serialize(
        {"format": FORMAT, "version": VERSION, "maneuvers": bool(model.maneuvers), "params": params}
    )


def save_weights(path: str | Path, model: CSLSTM, card: dict[str, Any] | None = None) -> None:
    """Write the weights (and their card, if given) atomically."""
    runtime.write_bytes(path, weights_to_bytes(model))
    if card is not None:
        runtime.write_json(card_path(path), card)


def model_from_bytes(data: bytes, source: str) -> CSLSTM:
    """Rebuild the network from `weights_to_bytes` output; anything else is one InputError."""
    try:
        tree = serialization.msgpack_restore(data)
    except Exception as e:  # noqa: BLE001 - any decoding failure is the same refusal
        raise InputError(f"{source}: not a msgpack weight file ({type(e).__name__})") from None
    if not isinstance(tree, dict) or tree.get("format") != FORMAT or tree.get("version") != VERSION:
        raise InputError(f"{source}: not a {FORMAT} v{VERSION} weight file")
    maneuvers = bool(tree.get("maneuvers"))
    expected = param_shapes(maneuvers)
    params = tree.get("params")
    if not isinstance(params, dict) or set(params) != set(expected):
        raise InputError(f"{source}: parameter groups do not match the CS-LSTM")
    for name, group in expected.items():
        if not isinstance(params[name], dict) or set(params[name]) != set(group):
            raise InputError(f"{source}: parameters of {name} do not match the CS-LSTM")
        for key, shape in group.items():
            got = np.asarray(params[name][key])
            if got.shape != shape or got.dtype.kind != "f" or not np.all(np.isfinite(got)):
                raise InputError(f"{source}: {name}.{key} is not a finite float array of shape {shape}")
    arrays = {k: {kk: np.asarray(vv, np.float32) for kk, vv in v.items()} for k, v in params.items()}
    return model_from_params(maneuvers, arrays)


def load_weights(path: str | Path) -> CSLSTM:
    """The network stored at `path` by `save_weights`."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise InputError(f"weight file not found: {path}") from None
    except OSError as e:
        raise InputError(f"cannot read weight file {path}: {e}") from None
    return model_from_bytes(data, str(path))


def read_card(weights_path: str | Path = DEFAULT_WEIGHTS) -> dict[str, Any]:
    """The model card (JSON) of a weight file."""
    path = card_path(weights_path)
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise InputError(
            f"no model card at {path}: train weights with `python -m diffsense.train --config "
            "configs/train/default.toml`"
        ) from None
    except (OSError, ValueError) as e:
        raise InputError(f"cannot read model card {path}: {e}") from None
