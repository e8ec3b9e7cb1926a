"""The contract between tracks and predictors: what a predictor eats, and the batch it is handed.

`InputSpec` is the one place a predictor's input contract is written (history and future
length, sample rate, social grid); `tracks` builds histories to it, the relevant-vehicle
selection sizes its search from it and the training-sample generator cuts samples to it.
`PredictorInputs` is the batch `tracks` hands over. Both live beneath the predictors, which
declare their spec and take the batch (`diffsense.predictors.Predictor`).
"""

from __future__ import annotations

import dataclasses
import math

import jax
from jaxtyping import Array, Float, Int

M_PER_FT = 0.3048  # international foot [m]


@dataclasses.dataclass(frozen=True)
class InputSpec:
    """A predictor's input contract (static, hashable).

    Attributes:
        history_points: points of the target's (and each neighbour's) history, the last one at
            the prediction instant [-].
        future_points: predicted points after the prediction instant [-].
        rate_hz: sample rate of history and future [Hz].
        grid_cells: longitudinal cells of the social grid, centred on the target [-].
        grid_lanes: lanes of the social grid: left, own, right [-].
        grid_cell_m: length of one grid cell along the road [m].
    """

    history_points: int
    future_points: int
    rate_hz: float
    grid_cells: int
    grid_lanes: int
    grid_cell_m: float

    def __post_init__(self):
        for name in ("history_points", "future_points", "grid_cells", "grid_lanes"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"InputSpec.{name} must be >= 1, got {getattr(self, name)}")
        if not (math.isfinite(self.rate_hz) and self.rate_hz > 0 and self.grid_cell_m > 0):
            raise ValueError("InputSpec.rate_hz and grid_cell_m must be positive")

    @property
    def history_s(self) -> float:
        """Span of the history window [s]."""
        return (self.history_points - 1) / self.rate_hz

    @property
    def future_s(self) -> float:
        """Span of the prediction horizon [s]."""
        return self.future_points / self.rate_hz

    @property
    def grid_size(self) -> int:
        """Slots of the social grid [-]."""
        return self.grid_cells * self.grid_lanes

    @property
    def grid_half_length_m(self) -> float:
        """Half the grid's length along the road: the reach of its outermost cells [m]."""
        return 0.5 * self.grid_cells * self.grid_cell_m

    def frames_per_point(self, scene_dt_s: float) -> int:
        """Scene frames between two predictor points; the scene rate must be a multiple."""
        ratio = 1.0 / (self.rate_hz * scene_dt_s)
        if abs(ratio - round(ratio)) > 1e-6 or round(ratio) < 1:
            raise ValueError(f"a {1 / scene_dt_s:g} Hz scene cannot feed a {self.rate_hz:g} Hz predictor")
        return int(round(ratio))

    def horizon_s(self) -> tuple[float, ...]:
        """Time of each predicted point after the prediction instant [s]."""
        return tuple((h + 1) / self.rate_hz for h in range(self.future_points))


# The CS-LSTM of Deo & Trivedi (2018) on NGSIM: 3 s of history and 5 s of future at 5 Hz, a
# 13 x 3 grid of 15 ft cells.
CSLSTM_SPEC = InputSpec(history_points=16, future_points=25, rate_hz=5.0, grid_cells=13,
                        grid_lanes=3, grid_cell_m=15.0 * M_PER_FT)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class PredictorInputs:
    """A batch of predictor inputs in SI, target road-aligned frame (lon forward, lat left).

    H is the spec's history_points. Attributes:
        hist: [B, H, 2] target history [m].
        nbr_hist: [B, M, H, 2] histories of the M candidate neighbours [m].
        nbr_slot: [B, M] grid id (lane * grid_cells + cell, lane 0 = left); 0 where not in the grid.
        nbr_weight: [B, M] grid occupancy in [0, 1]; 0 where not in the grid.
    """

    hist: Float[Array, "B H 2"]
    nbr_hist: Float[Array, "B M H 2"]
    nbr_slot: Int[Array, "B M"]
    nbr_weight: Float[Array, "B M"]
