"""The scene's output: ground-truth tracks every later stage consumes.

Conventions: SI units; road frame s forward along the reference line, d to the left
(ISO 8855); world frame x, y in metres with heading counter-clockwise from +x. Scenes are at
10 Hz. Vehicle index 0 is always the ego and index 1 the target (the vehicle whose trajectory is
predicted); the other roles are in `role`.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import jax
from jaxtyping import Array, Bool, Float, Int

# Vehicle kinds (index into per-kind tables such as radar cross-section).
CAR, VAN, TRUCK = 0, 1, 2
KIND_NAMES: tuple[str, ...] = ("car", "van", "truck")

# Roles in a scenario. EGO and TARGET are also fixed indices 0 and 1.
EGO, TARGET, LEAD, TARGET_LEAD, ADJACENT, BACKGROUND = 0, 1, 2, 3, 4, 5
ROLE_NAMES: tuple[str, ...] = ("ego", "target", "lead", "target_lead", "adjacent", "background")

EGO_INDEX = 0
TARGET_INDEX = 1


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Scene:
    """Ground-truth tracks of one scene (one scenario variant), T frames of V vehicles.

    A batch of variants has a leading axis N on every array field (vmap over variants).
    Arrays are padded to the scene's own vehicle count; `present` marks real vehicles.

    Attributes:
        s_m: [T, V] arc length along the road reference line [m].
        d_m: [T, V] lateral offset from the reference line, left positive [m].
        x_m: [T, V] world x of the vehicle reference point (centre of the body) [m].
        y_m: [T, V] world y [m].
        heading_rad: [T, V] world yaw of the vehicle body, counter-clockwise from +x [rad].
        road_angle_rad: [T, V] world yaw of the road reference line at s_m [rad].
        speed_mps: [T, V] longitudinal speed along the road [m/s].
        lane: [T, V] index of the lane the vehicle centre is in (0 = rightmost) [-].
        length_m: [V] body length [m].
        width_m: [V] body width [m].
        kind: [V] CAR, VAN or TRUCK.
        role: [V] EGO, TARGET, LEAD, TARGET_LEAD, ADJACENT or BACKGROUND.
        present: [V] True for real vehicles, False for padding.
        dt_s: frame period [s] (static; 0.1 for 10 Hz).
    """

    s_m: Float[Array, "*N T V"]
    d_m: Float[Array, "*N T V"]
    x_m: Float[Array, "*N T V"]
    y_m: Float[Array, "*N T V"]
    heading_rad: Float[Array, "*N T V"]
    road_angle_rad: Float[Array, "*N T V"]
    speed_mps: Float[Array, "*N T V"]
    lane: Int[Array, "*N T V"]
    length_m: Float[Array, "*N V"]
    width_m: Float[Array, "*N V"]
    kind: Int[Array, "*N V"]
    role: Int[Array, "*N V"]
    present: Bool[Array, "*N V"]
    dt_s: float = dataclasses.field(default=0.1, metadata=dict(static=True))

    ego_index: ClassVar[int] = EGO_INDEX
    target_index: ClassVar[int] = TARGET_INDEX

    @property
    def num_frames(self) -> int:
        return self.s_m.shape[-2]

    @property
    def num_vehicles(self) -> int:
        return self.s_m.shape[-1]
