"""How detection uncertainty enters the predictor: the estimator a user trades speed for accuracy with.

- `mean-field`: one pass on the expected histories (x = p z + (1 - p) fill) and soft occupancy.
- `mc`: K Monte-Carlo samples of relaxed-Bernoulli (binary Concrete) detections at temperature
  lambda, each a differentiable near-0/1 detection pattern; the objective is their mean. The
  uniform draws are fixed by a key (common random numbers), so the estimate is deterministic in r.
  A suite's members are drawn each on its own from their own uniforms, as E_ref draws them, and
  a sample's track is the fusion of the members that drew a detection.
- `relaxed-reference`: the reference's own Bernoulli draws (the uniforms of E_ref,
  `_reference.py`; the first `gradient_draws` of its K), each relaxed: detection
  sigmoid((logit p - logit u) / lambda) in place of 1[u < p]. As lambda -> 0 every relaxed draw
  becomes the reference's hard one, so the estimate tends to E_ref on those draws at every r (all
  K of them when gradient_draws >= K); lambda trades that bias for a gradient that sees more than
  the few draws on the edge of flipping. Under a deterministic
  detection law there is nothing to draw and it is mean-field.
- `straight-through`: the value of E_ref itself (the reference's K hard draws), the gradient of
  relaxed-reference (on its `gradient_draws`): E_ref + (E_relaxed - stop_gradient(E_relaxed)). The value no longer trades
  bias for smoothness, so lambda is chosen for the gradient alone. It costs relaxed-reference's
  evaluation plus K forward passes. The straight-through is taken on the whole objective, not on
  each draw: per draw, the gradient would be the objective's slope at the hard draw times the
  relaxed draw's, a linearisation of the predictor across a detection's flip, where the relaxed
  draw integrates the slope over it. Under a deterministic law it is mean-field, as
  relaxed-reference is.
- `auto` (the default): where the sensor declares a probabilistic detection law,
  `straight-through` for one free parameter and `relaxed-reference` for several
  (`Objective.estimator_kind` says why); mean-field otherwise (the threshold law, a custom sensor).
- `hard`: the sensor's own 0/1 detections (the reference; no gradient).
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from diffsense import runtime
from diffsense.runtime import InputError

Estimator = Literal["auto", "mean-field", "mc", "relaxed-reference", "straight-through", "hard"]
ESTIMATORS: tuple[str, ...] = ("auto", "mean-field", "mc", "relaxed-reference", "straight-through", "hard")

# p is clipped this far from 0 and 1 before its logit is taken; below it a detection is certain
# (or impossible) for any practical relaxation temperature.
_P_CLIP = 1e-6


@dataclasses.dataclass(frozen=True)
class EstimatorConfig:
    """Estimator choice and its knobs.

    Attributes:
        kind: "auto", "mean-field", "mc", "relaxed-reference", "straight-through" or "hard"
            (module docstring).
        samples: K, Monte-Carlo samples for "mc" [-].
        relax_temperature: lambda of the relaxed Bernoulli for "mc" [-]; -> 0 gives hard samples.
        reference_temperature: lambda of "relaxed-reference" and "straight-through" at
            temperature multiplier 1, in
            logit units [-]; the solver's continuation scales it like the gates' temperatures.
        reference_draws: K, Bernoulli draws per (frame, vehicle) of the reference objective
            E_ref (`Objective.reference`) [-]; unused by a deterministic detection law.
        gradient_draws: K_g, how many of those draws (the first min(K_g, K)) "relaxed-reference"
            relaxes, and "straight-through" takes its gradient from [-]. A gradient of the
            relaxed draws costs several values of E_ref at K (each draw's predictor pass is run
            forward, again in the backward pass, and backward), so a solve descends on a
            fraction of the draws, as stochastic optimisation descends on a mini-batch, and
            judges its answers on all K (`benchmarks/bench_design.py` measures the trade).
    """

    kind: Estimator = "auto"
    samples: int = 8
    relax_temperature: float = 0.5
    reference_draws: int = 32
    reference_temperature: float = 0.01
    gradient_draws: int = 8

    def __post_init__(self):
        if self.kind not in ESTIMATORS:
            raise InputError(f"unknown estimator {self.kind!r} (known: {', '.join(ESTIMATORS)})")
        if self.samples < 1:
            raise InputError(f"estimator samples must be >= 1, got {self.samples}")
        if self.reference_draws < 2:
            raise InputError(f"reference_draws must be >= 2 (a standard error needs two), got {self.reference_draws}")
        if self.gradient_draws < 1:
            raise InputError(f"gradient_draws must be >= 1, got {self.gradient_draws}")
        for name in ("relax_temperature", "reference_temperature"):
            if not getattr(self, name) > 0.0:
                raise InputError(f"{name} must be > 0, got {getattr(self, name)}")


def _clipped_logit(x: Array) -> Array:
    """log(x / (1 - x)) of x clipped into [_P_CLIP, 1 - _P_CLIP]: finite, with a finite gradient."""
    x = jnp.clip(x, _P_CLIP, 1.0 - _P_CLIP)
    return jnp.log(x) - jnp.log1p(-x)


def relaxed_bernoulli(p: Float[Array, "*S"], uniform: Float[Array, "*S"], temperature: float) -> Float[Array, "*S"]:
    """A binary-Concrete sample with mean-parameter p from fixed uniform draws in (0, 1)."""
    logistic_noise = jnp.log(uniform) - jnp.log1p(-uniform)  # mc_uniforms keeps u inside (0, 1)
    return jax.nn.sigmoid((_clipped_logit(p) + logistic_noise) / temperature)


def mc_uniforms(key: Array, samples: int, shape: tuple[int, ...], dtype) -> Float[Array, "K *S"]:
    """The fixed uniform draws of the Monte-Carlo estimator, strictly inside (0, 1)."""
    tiny = jnp.finfo(dtype).eps
    return runtime.uniform(key, (samples, *shape), dtype, tiny, 1.0 - tiny)


def relaxed_draw(p: Float[Array, "*S"], uniform: Float[Array, "*S"], temperature: Array) -> Float[Array, "*S"]:
    """The reference's draw 1[u < p] relaxed: sigmoid((logit p - logit u) / temperature).

    Both logits are taken of values clipped into (0, 1), so a p or u of exactly 0 or 1 gives a
    finite logit and a finite gradient; the clip changes a draw only where u or p lies within
    `_P_CLIP` of 0 or 1.
    """
    return jax.nn.sigmoid((_clipped_logit(p) - _clipped_logit(uniform)) / temperature)


@jax.custom_jvp
def straight_through(hard: Float[Array, "*S"], relaxed: Float[Array, "*S"]) -> Float[Array, "*S"]:
    """`hard`'s value (bit for bit), `relaxed`'s derivative; `hard` passes no derivative.

    `relaxed`'s value is never read, so a compiled program that needs no derivative drops its
    computation, and one that does computes it only where the derivative needs it.
    """
    return hard


@straight_through.defjvp
def _straight_through_jvp(primals, tangents):
    return primals[0], tangents[1]
