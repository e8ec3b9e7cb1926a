"""How detection uncertainty enters the predictor: the estimator a user trades speed for accuracy with.

- `mean-field`: one pass on the expected histories (x = p z + (1 - p) fill) and soft occupancy.
- `mc`: K Monte-Carlo samples of relaxed-Bernoulli (binary Concrete) detections at temperature
  lambda, each a differentiable near-0/1 detection pattern; the objective is their mean. The
  uniform draws are fixed by a key (common random numbers), so the estimate is deterministic in r.
- `hard`: the sensor's own 0/1 detections (the reference; no gradient).
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

Estimator = Literal["mean-field", "mc", "hard"]
ESTIMATORS: tuple[str, ...] = ("mean-field", "mc", "hard")

# p is clipped this far from 0 and 1 before its logit is taken; below it a detection is certain
# (or impossible) for any practical relaxation temperature.
_P_CLIP = 1e-6


@dataclasses.dataclass(frozen=True)
class EstimatorConfig:
    """Estimator choice and its knobs.

    Attributes:
        kind: "mean-field", "mc" or "hard".
        samples: K, Monte-Carlo samples for "mc" [-].
        relax_temperature: lambda of the relaxed Bernoulli for "mc" [-]; -> 0 gives hard samples.
        reference_draws: K, Bernoulli draws per (frame, vehicle) of the reference objective
            E_ref (`Objective.reference`) [-]; unused by a deterministic detection law.
    """

    kind: Estimator = "mean-field"
    samples: int = 8
    relax_temperature: float = 0.5
    reference_draws: int = 32

    def __post_init__(self):
        from diffsense.errors import InputError

        if self.kind not in ESTIMATORS:
            raise InputError(f"unknown estimator {self.kind!r} (known: {', '.join(ESTIMATORS)})")
        if self.samples < 1:
            raise InputError(f"estimator samples must be >= 1, got {self.samples}")
        if self.reference_draws < 2:
            raise InputError(f"reference_draws must be >= 2 (a standard error needs two), got {self.reference_draws}")
        if not self.relax_temperature > 0.0:
            raise InputError(f"relax_temperature must be > 0, got {self.relax_temperature}")


def relaxed_bernoulli(p: Float[Array, "*S"], uniform: Float[Array, "*S"], temperature: float) -> Float[Array, "*S"]:
    """A binary-Concrete sample with mean-parameter p from fixed uniform draws in (0, 1)."""
    p = jnp.clip(p, _P_CLIP, 1.0 - _P_CLIP)
    logit_p = jnp.log(p) - jnp.log1p(-p)
    logistic_noise = jnp.log(uniform) - jnp.log1p(-uniform)
    return jax.nn.sigmoid((logit_p + logistic_noise) / temperature)


def mc_uniforms(key: Array, samples: int, shape: tuple[int, ...], dtype) -> Float[Array, "K *S"]:
    """The fixed uniform draws of the Monte-Carlo estimator, strictly inside (0, 1)."""
    tiny = jnp.finfo(dtype).eps
    return jax.random.uniform(key, (samples, *shape), dtype=dtype, minval=tiny, maxval=1.0 - tiny)
