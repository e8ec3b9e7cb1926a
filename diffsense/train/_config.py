"""The training config (configs/train/*.toml), strict: unknown keys and wrong types are refused."""

from __future__ import annotations

import dataclasses

from diffsense.runtime import InputError


@dataclasses.dataclass(frozen=True)
class DataConfig:
    """path: dataset folder written by `python -m diffsense.scene generate` (meta.json + shards).
    val_fraction: share of simulations held out for validation (split by sim_id, never by sample:
    samples of one simulation are correlated). max_samples: use only the first N samples (0 = all).
    cv_points: history points whose mean velocity drives the constant-velocity baseline."""

    path: str
    val_fraction: float = 0.1
    max_samples: int = 0
    cv_points: int = 2

    def __post_init__(self):
        if not 0.0 < self.val_fraction < 1.0:
            raise InputError(f"data.val_fraction must be in (0, 1), got {self.val_fraction}")
        if self.max_samples < 0:
            raise InputError(f"data.max_samples must be >= 0, got {self.max_samples}")
        if not 2 <= self.cv_points <= 16:
            raise InputError(f"data.cv_points must be in 2..16, got {self.cv_points}")


@dataclasses.dataclass(frozen=True)
class OptimConfig:
    """The reference recipe (Deo & Trivedi's train.py): Adam, MSE epochs then NLL epochs.

    position_scale_ft: positions enter the network in units of this many feet during training
    (1 = the reference); the scale is folded into the first and last layers when the weights are
    written, so the result is a plain CS-LSTM in feet. lateral_scale_ft: the same for the lateral
    axis alone (0 = position_scale_ft): lateral offsets are ten times smaller than longitudinal
    ones, and one scale for both leaves them near zero at the network's input.
    mse_in_scaled_units: the MSE epochs measure the error in the scaled units (each axis in its
    own, so lateral errors weigh as much as longitudinal ones ten times their size) instead of
    in feet (the reference).
    schedule: "constant" (the reference) or "cosine": the learning rate decays along a half cosine
    over all steps of the run to `final_lr_fraction` x learning_rate."""

    learning_rate: float = 1e-3
    batch_size: int = 128
    clip_grad_norm: float = 10.0
    mse_epochs: int = 5
    nll_epochs: int = 3
    seed: int = 0
    position_scale_ft: float = 1.0
    lateral_scale_ft: float = 0.0
    mse_in_scaled_units: bool = False
    schedule: str = "constant"
    final_lr_fraction: float = 0.01

    def __post_init__(self):
        if self.schedule not in ("constant", "cosine"):
            raise InputError(f"optim.schedule must be 'constant' or 'cosine', got {self.schedule!r}")
        if not 0.0 <= self.final_lr_fraction <= 1.0:
            raise InputError(f"optim.final_lr_fraction must be in [0, 1], got {self.final_lr_fraction}")
        if not self.position_scale_ft > 0:
            raise InputError(f"optim.position_scale_ft must be > 0, got {self.position_scale_ft}")
        if not self.lateral_scale_ft >= 0:
            raise InputError(f"optim.lateral_scale_ft must be >= 0, got {self.lateral_scale_ft}")
        if not self.learning_rate > 0:
            raise InputError(f"optim.learning_rate must be > 0, got {self.learning_rate}")
        if self.batch_size < 1:
            raise InputError(f"optim.batch_size must be >= 1, got {self.batch_size}")
        if not self.clip_grad_norm > 0:
            raise InputError(f"optim.clip_grad_norm must be > 0, got {self.clip_grad_norm}")
        if self.mse_epochs < 0 or self.nll_epochs < 0 or self.mse_epochs + self.nll_epochs < 1:
            raise InputError("optim.mse_epochs and optim.nll_epochs must be >= 0 with at least one epoch")


@dataclasses.dataclass(frozen=True)
class RunConfig:
    """checkpoint_dir: where the resumable checkpoint goes; weights: the final msgpack (its model
    card is written next to it, same name with .json)."""

    checkpoint_dir: str = "runs/train"
    checkpoint_every_steps: int = 200
    weights: str = "diffsense/predictors/weights/cslstm.msgpack"
    val_batch_size: int = 512

    def __post_init__(self):
        if self.checkpoint_every_steps < 1:
            raise InputError(f"run.checkpoint_every_steps must be >= 1, got {self.checkpoint_every_steps}")
        if self.val_batch_size < 1:
            raise InputError(f"run.val_batch_size must be >= 1, got {self.val_batch_size}")


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    data: DataConfig
    maneuvers: bool = False
    optim: OptimConfig = OptimConfig()
    run: RunConfig = RunConfig()
