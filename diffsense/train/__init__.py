"""Training the CS-LSTM on generated traffic: `python -m diffsense.train --config FILE [--resume]`.

`train(cfg)` runs the reference recipe (Adam, gradient clipping, MSE then NLL epochs) on the
traffic generator's dataset, validates each epoch, checkpoints every N steps (resumable to the
same result) and writes the weights (msgpack) with a model card (JSON).
"""

from diffsense.train._config import DataConfig, OptimConfig, RunConfig, TrainConfig
from diffsense.train._data import Samples, load_samples, split_by_simulation
from diffsense.train._loop import train
from diffsense.train._metrics import constant_velocity_m, rmse_per_second

__all__ = [
    "DataConfig",
    "OptimConfig",
    "RunConfig",
    "Samples",
    "TrainConfig",
    "constant_velocity_m",
    "load_samples",
    "rmse_per_second",
    "split_by_simulation",
    "train",
]
