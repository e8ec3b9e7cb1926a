"""The training loop's bookkeeping with the network step replaced by one that records its batch:
step g takes batch g mod S of epoch g // S's permutation from numpy's generator seeded with
(seed, epoch), the MSE epochs before the NLL ones, the epoch's loss the mean of its steps (across
an interruption too), validation in fixed-size batches that wrap around, checkpoints every N
steps and at the end, the epoch lines, the model card; the checkpoint's refusals whole."""

from __future__ import annotations

import os
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import _tiny_traffic
from diffsense.config import from_dict, to_dict
from diffsense.runtime._errors import InputError
from diffsense.train import TrainConfig, constant_velocity_m, load_samples, rmse_per_second
from diffsense.train import _loop
from diffsense.train._data import split_by_simulation

BATCH, VAL_BATCH, EVERY = 16, 10, 3


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return _tiny_traffic.write(tmp_path_factory.mktemp("traffic") / "ds")  # 4 simulations of 24


def _cfg(tmp_path, data, **optim) -> TrainConfig:
    return from_dict(TrainConfig, {
        "data": {"path": str(data), "val_fraction": 0.25},
        "optim": {"batch_size": BATCH, "mse_epochs": 1, "nll_epochs": 1, "seed": 3, **optim},
        "run": {"checkpoint_dir": str(tmp_path / "ckpt"), "checkpoint_every_steps": EVERY,
                "weights": str(tmp_path / "w.msgpack"), "val_batch_size": VAL_BATCH},
    })


def _loss(hist) -> float:
    """The recording step's loss: a number each batch has of its own."""
    return float(np.asarray(hist, np.float64)[:, -3:, :].sum() / 1000.0)


@pytest.fixture
def recorded(monkeypatch):
    """Replaces the network step and the prediction; records what the loop hands them."""
    log = {"steps": [], "made": [], "val_calls": [], "saved": []}

    def make_step(graphdef, optim, total, maneuvers):
        log["made"].append((total, maneuvers))

        def step(params, opt_state, batch, use_nll):
            log["steps"].append((np.asarray(batch[0]), use_nll))
            return params, opt_state, jnp.float32(_loss(batch[0]))
        return step

    def make_predict(graphdef):
        def predict(params, hist, nbr_hist, nbr_slot, nbr_weight):
            log["val_calls"].append([np.asarray(a) for a in (hist, nbr_hist, nbr_slot, nbr_weight)])
            return jnp.zeros((hist.shape[0], 25, 2), jnp.float32)
        return predict

    save = _loop._save_checkpoint

    def save_checkpoint(path, cfg, step, *rest):
        log["saved"].append(step)
        save(path, cfg, step, *rest)

    monkeypatch.setattr(_loop, "time", SimpleNamespace(monotonic=lambda: 100.0))  # the loop's clock, stopped
    monkeypatch.setattr(_loop, "_make_step", make_step)
    monkeypatch.setattr(_loop, "_make_predict", make_predict)
    monkeypatch.setattr(_loop, "_save_checkpoint", save_checkpoint)
    return log


def _split(data):
    samples, _ = load_samples(data)
    return split_by_simulation(samples, 0.25, 3)


def _expected_batches(train_set, epochs: int) -> list[np.ndarray]:
    steps = len(train_set) // BATCH
    out = []
    for epoch in range(epochs):
        perm = np.random.default_rng([3, epoch]).permutation(len(train_set))
        out += [train_set.hist[perm[i * BATCH:(i + 1) * BATCH]] for i in range(steps)]
    return out


def _zero_prediction_rmse(val_set) -> list[float]:
    """RMSE at 1 .. 5 s [m] of a prediction of zeros: the true future's RMS distance."""
    d2 = (np.asarray(val_set.fut_m, np.float64) ** 2).sum(-1)
    return [float(np.sqrt(d2[:, k].mean())) for k in (4, 9, 14, 19, 24)]


def test_steps_take_the_seeded_permutation_phase_by_phase(tmp_path, data, recorded, capsys, monkeypatch):
    train_set, val_set = _split(data)
    assert (len(train_set), len(val_set)) == (72, 24)
    clock = iter([100.0])  # the run's start, then 0.26 s later for every reading after it
    monkeypatch.setattr(_loop, "time", SimpleNamespace(monotonic=lambda: next(clock, 100.26)))
    card = _loop.train(_cfg(tmp_path, data), progress=False)
    want = _expected_batches(train_set, 2)
    assert len(recorded["steps"]) == 8 and recorded["made"] == [(8, False)]
    for (got, _), batch in zip(recorded["steps"], want, strict=True):
        np.testing.assert_array_equal(got, batch)
    assert [nll for _, nll in recorded["steps"]] == [False] * 4 + [True] * 4
    assert recorded["saved"] == [3, 6, 8]
    losses = np.array([_loss(b) for b in want], np.float32)
    rmse = _zero_prediction_rmse(val_set)
    history = [{"epoch": e + 1, "phase": phase, "val_rmse_m": [round(r, 4) for r in rmse],
                "train_loss": pytest.approx(float(losses[4 * e:4 * e + 4].sum()) / 4, rel=1e-6)}
               for e, phase in enumerate(("mse", "nll"))]
    assert card["history"] == history
    lines = capsys.readouterr().out.splitlines()
    assert lines == [f"epoch {e + 1}/2 ({h['phase']}): train loss {losses[4 * e:4 * e + 4].sum() / 4:.4f}, "
                     f"val RMSE 1..5 s [m] {' '.join(f'{r:.2f}' for r in rmse)}" for e, h in enumerate(history)]
    # Validation: batches of 10 rows wrapping around the 24 samples, after each epoch and at the end.
    assert len(recorded["val_calls"]) == 3 * 3
    for call, rows in zip(recorded["val_calls"][:3], (range(10), range(10, 20), range(20, 30))):
        index = np.asarray(rows) % 24
        for got, want in zip(call, (val_set.hist, val_set.nbr_hist, val_set.nbr_slot, val_set.nbr_weight), strict=True):
            np.testing.assert_array_equal(got, want[index])
    assert card["steps"] == 8 and card["epochs"] == 2 and card["maneuvers"] is False
    assert card["model"] == "CS-LSTM (Deo & Trivedi 2018), single-mode decoder"
    assert card["data"] == {"path": str(data), "generator_seed": 0, "generator_config": {"tiny": True},
                            "num_train_samples": 72, "num_val_samples": 24, "num_val_simulations": 1}
    assert card["validation"]["rmse_m"]["cslstm"] == [round(r, 4) for r in rmse]
    cv = constant_velocity_m(val_set.hist_m, 2)
    assert card["validation"]["rmse_m"]["constant_velocity"] == [round(float(r), 4) for r in rmse_per_second(cv, val_set.fut_m)]
    assert card["validation"]["horizon_s"] == [1, 2, 3, 4, 5]
    assert card["parameters"] > 0 and card["wall_time_s"] == 0.3  # 0.26 s to a tenth
    assert card["frame"] == ("model frame: feet, lateral positive right (as the NGSIM checkpoints); "
                             "diffsense.predictors converts SI at its boundary")
    assert sorted(card["validation"]["rmse_by_axis_m"]) == ["constant_velocity", "cslstm"]
    assert sorted(card["validation"]["rmse_by_axis_m"]["cslstm"]) == ["lat", "lon"]
    assert sorted(card["software"]) == ["flax", "jax", "optax"]
    assert card["machine"] == {"platform": jax.default_backend(), "device": jax.devices()[0].device_kind,
                               "cpu_count": os.cpu_count()}
    assert (tmp_path / "w.msgpack").exists()


def test_an_interrupted_run_resumes_mid_epoch_as_if_never_stopped(tmp_path, data, recorded):
    train_set, _ = _split(data)
    full = _loop.train(_cfg(tmp_path / "full", data), progress=False)
    recorded["steps"].clear()
    recorded["saved"].clear()
    cfg = _cfg(tmp_path / "part", data)
    assert _loop.train(cfg, progress=False, stop_after_steps=5) == {}
    assert recorded["saved"] == [3] and not (tmp_path / "part" / "w.msgpack").exists()
    messages = []
    resumed = _loop.train(cfg, resume=True, progress=False, log=messages.append)
    assert messages == [f"resumed from {tmp_path / 'part' / 'ckpt' / 'last.msgpack'} at step 3/8"]
    got = [b for b, _ in recorded["steps"]]
    want = _expected_batches(train_set, 2)
    assert len(got) == 5 + 5  # steps 0-4, then 3-7 again from the checkpoint of step 3
    for a, b in zip(got, want[:5] + want[3:], strict=True):
        np.testing.assert_array_equal(a, b)
    assert recorded["saved"] == [3, 6, 8]
    assert resumed["history"] == full["history"]
    assert resumed["wall_time_s"] == full["wall_time_s"] == 0.0  # the checkpoint's wall time carried on


def test_the_progress_bar_counts_steps_and_shows_the_phase(tmp_path, data, recorded, capsys):
    _loop.train(_cfg(tmp_path, data, batch_size=8))  # shown by default; 9 steps an epoch: 18 in all
    err = capsys.readouterr().err
    assert "| 18/18 [" in err and "epoch=2, loss=" in err and "phase=nll]" in err and "phase=mse" not in err


def test_a_batch_larger_than_the_training_set_is_refused(tmp_path, data, recorded):
    with pytest.raises(InputError) as e:
        _loop.train(_cfg(tmp_path, data, batch_size=73), progress=False)
    assert str(e.value) == "72 training samples are fewer than one batch of 73"
    assert recorded["made"] == []


def test_the_checkpoint_round_trips_and_refuses_what_it_cannot_resume(tmp_path, data):
    cfg = _cfg(tmp_path, data)
    path = tmp_path / "c.msgpack"
    leaves = [np.arange(6, dtype=np.float32).reshape(2, 3), np.float32(2.5)]
    history = [{"epoch": 1, "phase": "mse", "train_loss": 0.5, "val_rmse_m": [1.0] * 5}]
    _loop._save_checkpoint(path, cfg, 7, leaves, history, 12.5, np.float32(3.25))
    step, got, hist, wall, loss_sum = _loop._load_checkpoint(path, cfg, leaves)
    assert (step, hist, wall, float(loss_sum)) == (7, history, 12.5, 3.25)
    for a, b in zip(got, leaves, strict=True):
        np.testing.assert_array_equal(a, b)
    other_run = from_dict(TrainConfig, {**to_dict(cfg), "run": {**to_dict(cfg)["run"], "checkpoint_every_steps": 9}})
    assert _loop._load_checkpoint(path, other_run, leaves)[0] == 7  # the run section may change
    for section, change in (("data", {"val_fraction": 0.5}), ("optim", {"seed": 4})):
        changed = from_dict(TrainConfig, {**to_dict(cfg), section: {**to_dict(cfg)[section], **change}})
        with pytest.raises(InputError) as e:
            _loop._load_checkpoint(path, changed, leaves)
        assert str(e.value) == f"--resume: the checkpoint {path} was made with a different '{section}' config"
    with pytest.raises(InputError) as e:
        _loop._load_checkpoint(path, from_dict(TrainConfig, {**to_dict(cfg), "maneuvers": True}), leaves)
    assert str(e.value) == f"--resume: the checkpoint {path} was made with a different 'maneuvers' config"
    with pytest.raises(InputError) as e:
        _loop._load_checkpoint(path, cfg, [np.zeros((3, 2), np.float32), np.float32(0)])
    assert str(e.value) == f"--resume: checkpoint {path} does not match the model"
    with pytest.raises(InputError) as e:
        _loop._load_checkpoint(tmp_path / "none", cfg, leaves)
    assert str(e.value) == f"--resume: no checkpoint at {tmp_path / 'none'}"
    path.write_bytes(b"\x81\xa4step\x07")  # a msgpack map without the rest
    with pytest.raises(InputError) as e:
        _loop._load_checkpoint(path, cfg, leaves)
    assert str(e.value).startswith(f"--resume: cannot read checkpoint {path}: KeyError: ")


def test_position_scale_is_lateral_then_longitudinal():
    from diffsense.train._config import OptimConfig

    np.testing.assert_array_equal(_loop.position_scale(OptimConfig(position_scale_ft=100.0)), [100.0, 100.0])
    np.testing.assert_array_equal(_loop.position_scale(OptimConfig(position_scale_ft=100.0, lateral_scale_ft=20.0)), [20.0, 100.0])
