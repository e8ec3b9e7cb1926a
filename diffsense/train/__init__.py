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
    concatenate_shards,
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
from diffsense.train._loop import fold_position_scale, position_scale, train
from diffsense.train._loss import class_bce, mse, nll
from diffsense.train._metrics import constant_velocity_m, rmse_per_second, rmse_per_second_by_axis
from diffsense.train._samples import (
    BRAKING,
    KEEP,
    LAYOUT_VERSION,
    LEFT,
    NORMAL,
    RIGHT,
    DenseSamples,
    extract_samples,
    lateral_label,
    longitudinal_label,
)

__all__ = [
    "LAYOUT_VERSION", "DenseSamples", "check_output_dir", "concatenate_shards", "extract_batch", "extract_samples",
    "generate_samples", "read_dataset", "read_meta", "read_shard", "samples_per_simulation", "shard_arrays",
    "simulate_batch", "simulation_keys", "write_dataset",
    # manoeuvre labels of a sample (the dataset layout's codes) and the rules that give them
    "BRAKING", "KEEP", "LEFT", "NORMAL", "RIGHT", "lateral_label", "longitudinal_label",
    # the training recipe: losses on raw decoder outputs, the position scale folded into the weights
    "class_bce", "mse", "nll", "fold_position_scale", "position_scale", "rmse_per_second_by_axis",
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
