"""What a sensor reports about a scene."""

from __future__ import annotations

import dataclasses

import jax
from jaxtyping import Array, Float


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Detections:
    """One sensor's view of one scene, per (frame, vehicle); a batch adds a leading axis N.

    The ego (vehicle 0) knows its own state: its `p_detect` is 1 and its position is the ground
    truth. Padding vehicles (`Scene.present` False) have `p_detect` 0.

    Attributes:
        p_detect: [T, V] detection probability in [0, 1] (soft mode; differentiable in the
            sensor parameters) or the 0/1 detection itself (hard mode).
        x_m: [T, V] measured world x of the vehicle centre (noisy) [m].
        y_m: [T, V] measured world y [m].
    """

    p_detect: Float[Array, "*N T V"]
    x_m: Float[Array, "*N T V"]
    y_m: Float[Array, "*N T V"]
