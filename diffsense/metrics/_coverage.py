"""Coverage: whether the sensor had the target at each prediction instant, and E split by it.

For prediction instant i (a scene frame t) the target's detections over the history window
t - H .. t (H = the predictor's history span, every scene frame) say how the sensor saw it:
- at_instant: detected at t itself;
- in_window: detected at least once in the window (the track exists: fill can hold or
  interpolate it);
- throughout: detected in every frame of the window.
With hard detections these are 0/1; with soft ones `p_tracked` is the probability of at least
one detection in the window, 1 - prod(1 - p), formed in log space (a product of many numbers
near 1 underflows nothing, and its gradient stays finite when every p is 0 or 1).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from diffsense.scene import TARGET_INDEX

_P_MAX = 1.0 - 1e-12  # log1p(-1) is -inf; a certain detection is clipped this close to 1


def target_window(p_detect: Float[Array, "T V"], frames: Int[Array, " I"], history_frames: int) -> Float[Array, "I W"]:
    """The target's detection probabilities over each instant's history window (oldest first)."""
    window = jnp.asarray(frames)[:, None] + jnp.arange(-history_frames, 1)[None, :]
    return p_detect[window, TARGET_INDEX]


def p_tracked(window_p: Float[Array, "*instants W"]) -> Float[Array, " *instants"]:
    """P(target detected at least once in the window) = 1 - prod(1 - p), in log space."""
    # Only the top is clipped: a clip's bound passes half the gradient, and p = 0 is common.
    log_miss = jnp.sum(jnp.log1p(-jnp.minimum(window_p, _P_MAX)), axis=-1)
    return -jnp.expm1(log_miss)


def coverage_classes(window_p: Float[Array, "I W"]) -> Float[Array, "I 3"]:
    """[at_instant, in_window, throughout] of hard (0/1) window detections, as 0/1 floats."""
    seen = window_p > 0.5
    return jnp.stack([seen[:, -1], jnp.any(seen, axis=-1), jnp.all(seen, axis=-1)], axis=-1).astype(window_p.dtype)


COVERAGE_PARTS = ("throughout", "partly", "never")


def coverage_parts(classes: np.ndarray) -> dict[str, np.ndarray]:
    """A partition of instants by coverage: tracked throughout, partly (in the window but not
    throughout), never (not once in the window). `classes` [..., 3] as from `coverage_classes`."""
    in_window, throughout = classes[..., 1] > 0.5, classes[..., 2] > 0.5
    return {"throughout": throughout, "partly": in_window & ~throughout, "never": ~in_window}
