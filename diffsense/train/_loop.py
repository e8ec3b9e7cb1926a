"""The training loop: reference recipe, seeded shuffling, validation each epoch, resumable.

Step g (0-based) of the run belongs to epoch g // steps_per_epoch and takes batch
g % steps_per_epoch of that epoch's permutation, drawn from numpy's generator seeded with
(seed, epoch). The model, the optimiser state, the step and the history are all that a resumed
run needs, so resuming from a checkpoint replays exactly what an uninterrupted run would do.
"""

from __future__ import annotations

import functools
import os
import time
from collections.abc import Callable
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import nnx, serialization

from diffsense import runtime
from diffsense.config import to_dict
from diffsense.predictors import (
    N_LAT,
    N_LON,
    model_to_si,
    new_model,
    save_weights,
    select_mean,
)
from diffsense.runtime import InputError
from diffsense.train._config import OptimConfig, TrainConfig
from diffsense.train._data import Samples, load_samples, split_by_simulation
from diffsense.train._loss import class_bce, mse, nll
from diffsense.train._metrics import (
    constant_velocity_m,
    rmse_per_second,
    rmse_per_second_by_axis,
)

CHECKPOINT_NAME = "last.msgpack"


def _batch(s: Samples, index: np.ndarray) -> tuple[np.ndarray, ...]:
    return (s.hist[index], s.fut[index], s.nbr_hist[index], s.nbr_slot[index], s.nbr_weight[index], s.lat[index], s.lon[index])


def _optimiser(optim: OptimConfig, total_steps: int) -> optax.GradientTransformation:
    """Adam after global-norm clipping, as the reference; the learning rate constant or a cosine
    decay over the whole run. The step count lives in the optimiser state, so a resumed run
    continues the schedule where it stopped."""
    lr = optim.learning_rate
    if optim.schedule == "cosine":
        lr = optax.cosine_decay_schedule(optim.learning_rate, max(total_steps, 1), alpha=optim.final_lr_fraction)
    return optax.chain(optax.clip_by_global_norm(optim.clip_grad_norm), optax.adam(lr))


def position_scale(optim: OptimConfig) -> np.ndarray:
    """Feet per network unit of the two position components in the model frame, [2] =
    (lateral, longitudinal)."""
    lateral = optim.lateral_scale_ft or optim.position_scale_ft
    return np.array([lateral, optim.position_scale_ft])


def fold_position_scale(params: nnx.State, scale) -> nnx.State:
    """The parameters of the plain network equal to the one trained with positions in units of
    `scale` feet (a number, or [2] per model-frame component): ip_emb(x / s) = (W / s) x + b and
    s * (W h + b) for the two mean outputs, exact linear algebra, so the shipped weights are a
    standard CS-LSTM in feet."""
    scale = np.broadcast_to(np.asarray(scale, np.float64), (2,))
    pure = jax.tree.map(lambda x: x, nnx.to_pure_dict(params))
    weight = pure["ip_emb"]["weight"]  # [2 inputs, E]
    pure["ip_emb"]["weight"] = weight / scale.astype(weight.dtype)[:, None]
    pure["op"]["weight"] = pure["op"]["weight"].at[:, :2].multiply(scale.astype(weight.dtype))
    pure["op"]["bias"] = pure["op"]["bias"].at[:2].multiply(scale.astype(weight.dtype))
    folded = jax.tree.map(lambda x: x, params)
    nnx.replace_by_pure_dict(folded, pure)
    return folded


@functools.lru_cache(maxsize=8)  # one compiled step per (structure, recipe): resumes reuse it
def _make_step(graphdef: nnx.GraphDef, optim: OptimConfig, total_steps: int, maneuvers: bool):
    tx = _optimiser(optim, total_steps)
    scale = position_scale(optim)

    def loss_fn(params, batch, use_nll: bool):
        hist, fut, nbr_hist, nbr_slot, nbr_weight, lat, lon = batch
        model = nnx.merge(graphdef, params)
        # Positions enter in units of `scale` ft and the means leave in ft (see fold_position_scale).
        s = jnp.asarray(scale, hist.dtype)
        enc = model.context_compact(hist / s, nbr_hist / s, nbr_slot, nbr_weight)
        if maneuvers:  # teacher forcing with the true manoeuvre, as the reference trains
            onehots = [jax.nn.one_hot(lat, N_LAT, dtype=enc.dtype), jax.nn.one_hot(lon, N_LON, dtype=enc.dtype)]
            raw = model.decode_raw(jnp.concatenate([enc, *onehots], axis=-1))
        else:
            raw = model.decode_raw(enc)
        if not use_nll and optim.mse_in_scaled_units:
            return mse(raw, fut / s)
        raw = jnp.concatenate([raw[..., :2] * s, raw[..., 2:]], axis=-1)
        if not use_nll:
            return mse(raw, fut)
        loss = nll(raw, fut)
        if maneuvers:
            loss = loss + class_bce(model.op_lat(enc), lat) + class_bce(model.op_lon(enc), lon)
        return loss

    def step(params, opt_state, batch, use_nll: bool):
        loss, grads = jax.value_and_grad(loss_fn)(params, batch, use_nll)
        updates, opt_state = tx.update(grads, opt_state, params)
        return optax.apply_updates(params, updates), opt_state, loss

    return jax.jit(step, static_argnums=3)


@functools.lru_cache(maxsize=8)
def _make_predict(graphdef: nnx.GraphDef):
    def predict(params, hist, nbr_hist, nbr_slot, nbr_weight):
        """Mean future in SI (most probable manoeuvre for the manoeuvre variant)."""
        pred = nnx.merge(graphdef, params).compact(hist, nbr_hist, nbr_slot, nbr_weight)
        return model_to_si(select_mean(pred, "most_probable"))

    return jax.jit(predict)


def _validate(predict, params, val: Samples, batch_size: int) -> np.ndarray:
    """Predicted future means [S, 25, 2] in SI, in fixed-size batches (the last one padded)."""
    out = []
    for first in range(0, len(val), batch_size):
        index = np.arange(first, first + batch_size) % len(val)
        mean = predict(params, val.hist[index], val.nbr_hist[index], val.nbr_slot[index], val.nbr_weight[index])
        out.append(np.asarray(mean)[: len(val) - first])
    return np.concatenate(out)


def _save_checkpoint(path: Path, cfg: TrainConfig, step: int, leaves, history, wall_s: float, epoch_loss) -> None:
    payload = {
        "epoch_loss_sum": np.asarray(epoch_loss),  # running sum over the current epoch's steps
        "config": serialization.msgpack_serialize(to_dict(cfg)),
        "step": step,
        "wall_s": wall_s,
        "history": serialization.msgpack_serialize(history),
        "leaves": {str(i): np.asarray(x) for i, x in enumerate(leaves)},
    }
    runtime.write_bytes(path, serialization.msgpack_serialize(payload))


def _load_checkpoint(path: Path, cfg: TrainConfig, template_leaves) -> tuple[int, list, list, float, np.ndarray]:
    try:
        payload = serialization.msgpack_restore(path.read_bytes())
        saved_cfg = serialization.msgpack_restore(payload["config"])
        leaves = [np.asarray(payload["leaves"][str(i)]) for i in range(len(template_leaves))]
        step, wall_s = int(payload["step"]), float(payload["wall_s"])
        history = serialization.msgpack_restore(payload["history"])
        epoch_loss = np.asarray(payload["epoch_loss_sum"])
    except FileNotFoundError:
        raise InputError(f"--resume: no checkpoint at {path}") from None
    except Exception as e:  # noqa: BLE001 - any malformed checkpoint is the same refusal
        raise InputError(f"--resume: cannot read checkpoint {path}: {type(e).__name__}: {e}") from None
    current = to_dict(cfg)
    for section in ("data", "maneuvers", "optim"):
        if saved_cfg.get(section) != current[section]:
            raise InputError(f"--resume: the checkpoint {path} was made with a different '{section}' config")
    for got, want in zip(leaves, template_leaves):
        if got.shape != np.shape(want):
            raise InputError(f"--resume: checkpoint {path} does not match the model")
    return step, leaves, list(history), wall_s, epoch_loss


def train(
    cfg: TrainConfig,
    resume: bool = False,
    progress: bool = True,
    stop_after_steps: int | None = None,
    log: Callable[[str], None] = print,
) -> dict:
    """Train, validate each epoch, checkpoint every N steps, and write weights + model card.

    Returns the model card. `stop_after_steps` ends the run early without writing weights (an
    interruption, for tests of `resume`).
    """
    from tqdm import tqdm

    samples, meta = load_samples(cfg.data.path, cfg.data.max_samples)
    train_set, val_set = split_by_simulation(samples, cfg.data.val_fraction, cfg.optim.seed)
    bs = cfg.optim.batch_size
    steps_per_epoch = len(train_set) // bs
    if steps_per_epoch == 0:
        raise InputError(f"{len(train_set)} training samples are fewer than one batch of {bs}")
    epochs = cfg.optim.mse_epochs + cfg.optim.nll_epochs
    total = epochs * steps_per_epoch

    ckpt = Path(cfg.run.checkpoint_dir) / CHECKPOINT_NAME
    graphdef, params, opt_state, start, history, wall_before, loss_sum = _initial_state(cfg, total, ckpt, resume, log)

    scale = position_scale(cfg.optim)
    step_fn = _make_step(graphdef, cfg.optim, total, cfg.maneuvers)
    predict = _make_predict(graphdef)
    t0 = time.monotonic()
    bar = tqdm(total=total, initial=start, disable=not progress, unit="step", dynamic_ncols=True)
    perm_epoch, perm = -1, None
    for g in range(start, total):
        epoch, i = divmod(g, steps_per_epoch)
        if epoch != perm_epoch:
            perm_epoch, perm = epoch, np.random.default_rng([cfg.optim.seed, epoch]).permutation(len(train_set))
            if i == 0:
                loss_sum = jnp.zeros((), jnp.float32)
        use_nll = epoch >= cfg.optim.mse_epochs
        batch = _batch(train_set, perm[i * bs : (i + 1) * bs])
        params, opt_state, loss = step_fn(params, opt_state, batch, use_nll)
        loss_sum = loss_sum + loss.astype(jnp.float32)
        bar.update(1)
        if (g + 1) % 10 == 0:
            bar.set_postfix(epoch=epoch + 1, phase="nll" if use_nll else "mse", loss=f"{float(loss):.3f}")
        if (g + 1) % steps_per_epoch == 0:
            fut = _validate(predict, fold_position_scale(params, scale), val_set, cfg.run.val_batch_size)
            record, rmse = _epoch_record(epoch, use_nll, float(loss_sum) / steps_per_epoch, fut, val_set)
            history.append(record)
            bar.write(f"epoch {epoch + 1}/{epochs} ({record['phase']}): train loss {record['train_loss']:.4f}, "
                      f"val RMSE 1..5 s [m] {' '.join(f'{r:.2f}' for r in rmse)}")
        done = g + 1
        if done % cfg.run.checkpoint_every_steps == 0 or done == total:
            wall = wall_before + time.monotonic() - t0
            _save_checkpoint(ckpt, cfg, done, jax.tree.leaves((params, opt_state)), history, wall, loss_sum)
        if stop_after_steps is not None and done >= stop_after_steps and done < total:
            bar.close()
            return {}
    bar.close()
    wall = wall_before + time.monotonic() - t0

    params = fold_position_scale(params, scale)
    fut = _validate(predict, params, val_set, cfg.run.val_batch_size)
    card = _model_card(cfg, params, fut, train_set, val_set, meta, total, epochs, wall, history)
    save_weights(cfg.run.weights, nnx.merge(graphdef, params), card)
    return card


def _initial_state(cfg: TrainConfig, total: int, ckpt: Path, resume: bool, log: Callable[[str], None]):
    """(graphdef, params, opt_state, first step, history, wall time before [s], epoch loss sum):
    a new model, or the checkpoint's state when resuming."""
    graphdef, params = nnx.split(new_model(cfg.maneuvers, cfg.optim.seed))
    opt_state = _optimiser(cfg.optim, total).init(params)
    leaves, treedef = jax.tree.flatten((params, opt_state))
    # The epoch's training loss is summed on the device (no sync per step) and checkpointed, so
    # a run resumed mid-epoch reports the same epoch loss as an uninterrupted one.
    if not resume:
        return graphdef, params, opt_state, 0, [], 0.0, jnp.zeros((), jnp.float32)
    start, leaves, history, wall_before, saved_sum = _load_checkpoint(ckpt, cfg, leaves)
    params, opt_state = jax.tree.unflatten(treedef, [jnp.asarray(x) for x in leaves])
    log(f"resumed from {ckpt} at step {start}/{total}")
    return graphdef, params, opt_state, start, history, wall_before, jnp.asarray(saved_sum, jnp.float32)


def _epoch_record(epoch: int, use_nll: bool, train_loss: float, fut, val_set) -> tuple[dict, np.ndarray]:
    """The history entry of a finished epoch (its phase, mean training loss and validation RMSE
    per second of horizon, rounded to 0.1 mm) and that RMSE unrounded [m]."""
    rmse = rmse_per_second(fut, val_set.fut_m)
    return {"epoch": epoch + 1, "phase": "nll" if use_nll else "mse", "train_loss": train_loss,
            "val_rmse_m": [round(float(r), 4) for r in rmse]}, rmse


def _model_card(cfg: TrainConfig, params, fut, train_set, val_set, meta: dict, total: int, epochs: int,
                wall: float, history: list[dict]) -> dict:
    """The model card of a finished run: what was trained on what, and how it validates against
    constant velocity (`fut`: the trained model's predictions of the validation set)."""
    cv = constant_velocity_m(val_set.hist_m, cfg.data.cv_points)
    card = {
        "model": "CS-LSTM (Deo & Trivedi 2018), " + ("manoeuvre-based decoder" if cfg.maneuvers else "single-mode decoder"),
        "maneuvers": cfg.maneuvers,
        "parameters": int(sum(np.size(x) for x in jax.tree.leaves(params))),
        "frame": "model frame: feet, lateral positive right (as the NGSIM checkpoints); "
                 "diffsense.predictors converts SI at its boundary",
        "train_config": to_dict(cfg),
        "data": {
            "path": cfg.data.path,
            "generator_seed": meta.get("seed"),
            "generator_config": meta.get("config"),
            "num_train_samples": len(train_set),
            "num_val_samples": len(val_set),
            "num_val_simulations": int(len(np.unique(val_set.sim_id))),
        },
        "steps": total,
        "epochs": epochs,
        "wall_time_s": round(wall, 1),
        "validation": {
            "horizon_s": [1, 2, 3, 4, 5],
            "rmse_m": {
                "cslstm": [round(float(r), 4) for r in rmse_per_second(fut, val_set.fut_m)],
                "constant_velocity": [round(float(r), 4) for r in rmse_per_second(cv, val_set.fut_m)],
            },
            "rmse_by_axis_m": {  # road frame: lon forward, lat left
                "cslstm": rmse_per_second_by_axis(fut, val_set.fut_m),
                "constant_velocity": rmse_per_second_by_axis(cv, val_set.fut_m),
            },
        },
        "history": history,
        "software": {"jax": jax.__version__, "flax": __import__("flax").__version__, "optax": optax.__version__},
        "machine": {"platform": jax.default_backend(), "device": jax.devices()[0].device_kind,
                    "cpu_count": os.cpu_count()},
    }
    return card
