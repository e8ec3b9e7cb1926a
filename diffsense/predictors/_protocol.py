"""What a trajectory predictor is to diffsense: an input spec and a pure call.

The spec and the batch it is called on (`InputSpec`, `PredictorInputs`) are the tracks stage's
(`diffsense.tracks`), which builds the batch to the spec.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from jaxtyping import Array, Float

from diffsense.tracks import InputSpec, PredictorInputs


@runtime_checkable
class Predictor(Protocol):
    """A trajectory predictor: any pytree with an input spec and a pure, differentiable call.

    `predictor(inputs)` maps `PredictorInputs` (batch B) to the target's future mean positions
    [B, spec.future_points, 2] in the same SI frame. It must be traceable (jit, grad in the
    inputs), since E(r) differentiates through it; parameters are pytree leaves, so jit does
    not bake them in.
    """

    spec: InputSpec

    def __call__(self, inputs: PredictorInputs) -> Float[Array, "B F 2"]: ...
