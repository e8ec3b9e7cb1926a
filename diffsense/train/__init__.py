"""Training the CS-LSTM on generated traffic: samples, datasets and the training loop.

    python -m diffsense.scene generate --out DIR     # write a training set (the sample layout: _samples.py)
    python -m diffsense.train --config FILE          # train on it

`train(cfg)` runs the reference recipe (Adam, gradient clipping, MSE then NLL epochs) on the
traffic generator's dataset, validates each epoch, checkpoints every N steps (resumable to the
same result) and writes the weights (msgpack) with a model card (JSON).
"""

from diffsense.train._config import DataConfig, OptimConfig, RunConfig, TrainConfig
from diffsense.train._data import Samples, load_samples, split_by_simulation
from diffsense.train._dataset import (
    check_output_dir,
    extract_batch,
    generate_samples,
    read_dataset,
    read_meta,
    read_shard,
    samples_per_simulation,
    shard_arrays,
    simulate_batch,
    simulation_keys,
    write_dataset,
)
from diffsense.train._loop import train
from diffsense.train._metrics import constant_velocity_m, rmse_per_second
from diffsense.train._samples import LAYOUT_VERSION, DenseSamples, extract_samples

__all__ = [
    "LAYOUT_VERSION", "DenseSamples", "check_output_dir", "extract_batch", "extract_samples", "generate_samples", "read_dataset",
    "read_meta", "read_shard", "samples_per_simulation", "shard_arrays", "simulate_batch", "simulation_keys",
    "write_dataset",
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
