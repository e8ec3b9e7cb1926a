"""`diffsense predict` (and `python -m diffsense.predictors`): parity with the PyTorch reference,
and the default model card.

  parity --checkpoint PATH --inputs IN.npz --out OUT.npz
      IN.npz: hist [16, B, 2], nbrs [16, N, 2], mask [B, 3, 13, 64] bool (the reference's layout,
      feet); OUT.npz: what the reference forward returns in evaluation mode (fut_pred, and
      lat_pred / lon_pred for the manoeuvre variant). Written atomically.
  card [--weights PATH]
      print the model card (JSON) of the default shipped weights (or of PATH).
"""

from __future__ import annotations

import argparse
import io
import json
import zipfile
from pathlib import Path

import numpy as np

from diffsense import runtime
from diffsense.cli import Parser
from diffsense.predictors import DEFAULT_WEIGHTS, load_predictor, read_card, reference_forward
from diffsense.runtime import InputError

PROG = "python -m diffsense.predictors"


def _read_npz(path: Path) -> dict[str, np.ndarray]:
    try:
        with np.load(path, allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
    except FileNotFoundError:
        raise InputError(f"inputs not found: {path}") from None
    except (OSError, ValueError, zipfile.BadZipFile) as e:
        raise InputError(f"cannot read inputs {path}: {e}") from None
    missing = [k for k in ("hist", "nbrs", "mask") if k not in arrays]
    if missing:
        raise InputError(f"{path}: missing array '{missing[0]}' (needs hist, nbrs, mask)")
    return arrays


def _parity(args: argparse.Namespace) -> int:
    arrays = _read_npz(Path(args.inputs))
    predictor = load_predictor(args.checkpoint)
    out = reference_forward(predictor, arrays["hist"], arrays["nbrs"], arrays["mask"], args.inputs)
    buf = io.BytesIO()
    np.savez(buf, **out)
    runtime.write_bytes(args.out, buf.getvalue())
    shapes = ", ".join(f"{k} {list(v.shape)}" for k, v in out.items())
    print(f"wrote {args.out}: {shapes}")
    return 0


def _card(args: argparse.Namespace) -> int:
    print(json.dumps(read_card(args.weights or DEFAULT_WEIGHTS), indent=2))
    return 0


def main(argv: list[str] | None = None, prog: str = PROG) -> int:
    parser = Parser(prog=prog, description="The predictor: parity with the PyTorch reference, and the model card.")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("parity", help="reference-layout forward pass of a checkpoint")
    p.add_argument("--checkpoint", required=True, help="published PyTorch checkpoint or .msgpack")
    p.add_argument("--inputs", required=True, help="npz with hist, nbrs, mask (reference layout)")
    p.add_argument("--out", required=True, help="npz to write (atomically)")
    c = sub.add_parser("card", help="print the model card of the default weights")
    c.add_argument("--weights", default=None, help="a .msgpack weight file instead of the default")
    args = parser.parse_args(argv)
    return _parity(args) if args.command == "parity" else _card(args)
