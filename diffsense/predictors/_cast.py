"""A predictor run at its own float precision inside an objective of another.

E(r) runs in float64 by default: the solver differentiates a near-flat objective and needs the
digits. The predictor does not: its weights are float32 (it was trained in float32), so float64
arithmetic inside it adds only rounding digits, at about twice the cost on a CPU.
`with_compute_dtype(predictor, "float32")` casts the inputs down, runs the predictor, and casts
its output back up; the gradient flows through both casts (the cast's derivative is the
identity), so E and dE/dr keep float64 everywhere except inside the network.

"bfloat16" is float32 arithmetic whose LSTM matrix products take bfloat16 operands into float32
sums (the mixed precision accelerators train in): the products, most of a CS-LSTM pass, run at
about twice float32's rate on a CPU with AVX512-BF16. Its operands keep 8 significant bits, so
predictions move by centimetres (a speed the user buys with accuracy: docs/speed-accuracy.md).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from diffsense.tracks import InputSpec, PredictorInputs

COMPUTE_DTYPES = ("float32", "float64", "bfloat16")


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class CastPredictor:
    """`inner` computed in `dtype`, its inputs and output in the caller's dtype (a `Predictor`).

    Attributes:
        inner: any `Predictor` (its parameters stay pytree leaves).
        dtype: the float dtype inside the predictor, "float32" or "float64", or "bfloat16"
            (float32 with bfloat16 products: `inner` is a CS-LSTM whose `product_dtype` says so).
    """

    inner: Any
    dtype: str = dataclasses.field(metadata=dict(static=True))

    @property
    def spec(self) -> InputSpec:
        return self.inner.spec

    @property
    def validation_rmse_m(self) -> tuple[float, ...] | None:
        """The inner predictor's validation RMSE at 1, 2, ... s (None when unknown)."""
        return getattr(self.inner, "validation_rmse_m", None)

    def __call__(self, inputs: PredictorInputs) -> Float[Array, "B F 2"]:
        out_dtype = inputs.hist.dtype

        inside = "float32" if self.dtype == "bfloat16" else self.dtype

        def cast(a):
            return a.astype(inside) if jnp.issubdtype(a.dtype, jnp.floating) else a

        return self.inner(jax.tree.map(cast, inputs)).astype(out_dtype)


def with_compute_dtype(predictor: Any, dtype: str | None) -> Any:
    """`predictor` computing in `dtype` ("float32", "float64" or "bfloat16"); None returns it
    unchanged, and a predictor already cast is re-cast from its inner one (never two casts deep).
    "bfloat16" needs a CS-LSTM (its LSTM products are what it changes)."""
    if dtype is None:
        return predictor
    if dtype not in COMPUTE_DTYPES:
        raise ValueError(f"predictor dtype must be one of {', '.join(COMPUTE_DTYPES)}, got {dtype!r}")
    inner = predictor.inner if isinstance(predictor, CastPredictor) else predictor
    if hasattr(inner, "product_dtype"):
        inner = dataclasses.replace(inner, product_dtype="bfloat16" if dtype == "bfloat16" else None)
    elif dtype == "bfloat16":
        raise ValueError(f"bfloat16 products are a CS-LSTM's; {type(inner).__name__} has none")
    return CastPredictor(inner=inner, dtype=dtype)
