"""Training the CS-LSTM on a tiny dataset: a run resumed from its checkpoint ends as the
uninterrupted one, the model card holds what the written weights predict on the validation split,
the MSE in scaled units means what it says, a resume is refused for another config, and the
command line fails in one line."""

from __future__ import annotations

import subprocess
import sys

import _tiny_traffic
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.config import from_dict
from diffsense.predictors import (
    load_predictor,
    load_weights,
    model_to_si,
    predict_mean,
    read_card,
    state_dict_from_model,
)
from diffsense.runtime import InputError
from diffsense.train import (
    TrainConfig,
    constant_velocity_m,
    load_samples,
    rmse_per_second,
    split_by_simulation,
    train,
)


def _cfg(tmp_path, data, name: str, maneuvers: bool = False, val_fraction: float = 0.25, **optim) -> TrainConfig:
    return from_dict(TrainConfig, {
        "maneuvers": maneuvers,
        "data": {"path": str(data), "val_fraction": val_fraction},
        "optim": {"batch_size": 16, "mse_epochs": 1, "nll_epochs": 1, "seed": 3, **optim},
        "run": {"checkpoint_dir": str(tmp_path / name / "ckpt"), "checkpoint_every_steps": 3,
                "weights": str(tmp_path / name / "w.msgpack"), "val_batch_size": 10},
    })


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return _tiny_traffic.write(tmp_path_factory.mktemp("traffic") / "ds")  # 4 simulations of 24 samples


def _silent(cfg, **kw):
    return train(cfg, progress=False, log=lambda _: None, **kw)


def test_resume_equals_uninterrupted_and_is_refused_for_another_config(tmp_path, data):
    # The manoeuvre variant (every loss term: NLL and both class losses), NLL epochs only (one
    # compiled step), the cosine schedule: its position must survive the interruption too.
    run = dict(maneuvers=True, mse_epochs=0, nll_epochs=2, schedule="cosine")
    card = _silent(_cfg(tmp_path, data, "full", **run))
    part = _cfg(tmp_path, data, "part", **run)
    assert _silent(part, stop_after_steps=5) == {}  # interrupted after step 5 of 8
    assert not (tmp_path / "part" / "w.msgpack").exists()
    for section, change in (("optim", {"seed": 4}), ("maneuvers", {"maneuvers": False}), ("data", {"val_fraction": 0.5})):
        with pytest.raises(InputError, match=f"'{section}'"):
            _silent(_cfg(tmp_path, data, "part", **run | change), resume=True)
    # Resumes from the checkpoint of step 3, in the middle of the first epoch (4 steps each).
    resumed = _silent(part, resume=True)
    a = state_dict_from_model(load_weights(tmp_path / "full" / "w.msgpack"))
    b = state_dict_from_model(load_weights(tmp_path / "part" / "w.msgpack"))
    assert all(np.array_equal(a[k], b[k]) for k in a)
    assert resumed["history"] == card["history"] and resumed["validation"] == card["validation"]
    assert [h["phase"] for h in card["history"]] == ["nll", "nll"]
    assert card["steps"] == 2 * (72 // 16) and card["epochs"] == 2 and card["maneuvers"] is True
    assert read_card(tmp_path / "full" / "w.msgpack") == card


def _val_rmse(weights, val) -> np.ndarray:
    """RMSE at 1 .. 5 s [m] of the weights' predictions of the validation samples, through the
    public SI entry point."""
    predictor = load_predictor(weights)
    mean = jax.jit(predict_mean)(predictor, val.hist_m, model_to_si(val.nbr_hist), val.nbr_slot, val.nbr_weight)
    assert mean.dtype == jnp.float32 and mean.shape == (len(val), 25, 2)
    return rmse_per_second(mean, val.fut_m)


@pytest.fixture(scope="module")
def single_mode_runs(tmp_path_factory, data):
    """Two single-mode MSE epochs at a learning rate too small to move the network: positions in
    units of 100 ft (20 ft lateral), the error measured in feet and in the scaled units."""
    tmp_path = tmp_path_factory.mktemp("runs")
    kw = dict(mse_epochs=1, nll_epochs=0, learning_rate=1e-12, position_scale_ft=100.0, lateral_scale_ft=20.0)
    return {scaled: (_silent(_cfg(tmp_path, data, str(scaled), mse_in_scaled_units=scaled, **kw)),
                     tmp_path / str(scaled) / "w.msgpack") for scaled in (False, True)}


def test_the_card_holds_what_the_weights_predict_on_the_validation_split(single_mode_runs, data):
    card, weights = single_mode_runs[False]
    samples, _ = load_samples(data)
    train_set, val = split_by_simulation(samples, 0.25, seed=3)
    assert card["data"] == {"path": str(data), "generator_seed": 0, "generator_config": {"tiny": True},
                            "num_train_samples": 72, "num_val_samples": 24, "num_val_simulations": 1}
    assert (len(train_set), len(val)) == (72, 24) and card["steps"] == 72 // 16 and card["maneuvers"] is False
    rmse = card["validation"]["rmse_m"]
    assert card["validation"]["horizon_s"] == [1, 2, 3, 4, 5]
    np.testing.assert_allclose(rmse["cslstm"], _val_rmse(weights, val), atol=1e-4)  # the card rounds to 0.1 mm
    np.testing.assert_allclose(rmse["constant_velocity"], rmse_per_second(constant_velocity_m(val.hist_m, 2), val.fut_m),
                               atol=5e-5)
    for model, total in rmse.items():
        axes = card["validation"]["rmse_by_axis_m"][model]
        np.testing.assert_allclose(np.hypot(axes["lon"], axes["lat"]), total, atol=2e-4)
    assert card["history"][0]["val_rmse_m"] == rmse["cslstm"]
    assert sorted(card["software"]) == ["flax", "jax", "optax"] and card["parameters"] > 0
    assert weights.stat().st_size < 2_000_000


def test_the_mse_in_scaled_units_weighs_each_axis_in_its_own_unit(single_mode_runs):
    # The same network and batches: the scaled loss is the feet loss with each axis divided by its
    # scale squared, so it lies between the two bounds.
    feet, scaled = (single_mode_runs[s][0]["history"][0]["train_loss"] for s in (False, True))
    assert np.isfinite(feet) and feet / 100.0**2 < scaled < feet / 20.0**2


def test_what_cannot_be_trained_is_refused(tmp_path, data):
    with pytest.raises(InputError, match="73"):
        _silent(_cfg(tmp_path, data, "big", batch_size=73))  # 72 training samples: not one batch
    cfg = _cfg(tmp_path, data, "none")
    with pytest.raises(InputError, match=str(tmp_path / "none" / "ckpt")):
        _silent(cfg, resume=True)  # no checkpoint
    (tmp_path / "none" / "ckpt").mkdir(parents=True)
    (tmp_path / "none" / "ckpt" / "last.msgpack").write_bytes(b"\x81\xa4step\x07")  # a map without the rest
    with pytest.raises(InputError, match=str(tmp_path / "none" / "ckpt")):
        _silent(cfg, resume=True)


def test_cli_bad_config_is_one_line(tmp_path):
    for text, culprit in (('maneuvers = false\n[data]\npath = "x"\nvall_fraction = 0.1\n', "data.vall_fraction"),
                          (f'[data]\npath = "{tmp_path / "absent"}"\n', str(tmp_path / "absent"))):
        (tmp_path / "c.toml").write_text(text)
        proc = subprocess.run([sys.executable, "-m", "diffsense.train", "--config", str(tmp_path / "c.toml")],
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 2 and culprit in proc.stderr, proc.stderr
        assert proc.stderr.strip().count("\n") == 0
