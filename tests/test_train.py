"""Training: resume equals an uninterrupted run, the model card, losses finite, config errors."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import _tiny_traffic
from diffsense.config import from_dict
from diffsense.runtime._errors import InputError
from diffsense.predictors import load_predictor, predict_mean, read_card, state_dict_from_model
from diffsense.predictors import load_weights
from diffsense.train import TrainConfig, constant_velocity_m, load_samples, rmse_per_second, train
from diffsense.train._loss import class_bce, mse, nll


def _cfg(tmp_path, data, name: str, maneuvers: bool = False, **optim) -> TrainConfig:
    return from_dict(TrainConfig, {
        "maneuvers": maneuvers,
        "data": {"path": str(data), "val_fraction": 0.25},
        "optim": {"batch_size": 16, "mse_epochs": 1, "nll_epochs": 1, "seed": 3, **optim},
        "run": {"checkpoint_dir": str(tmp_path / name / "ckpt"), "checkpoint_every_steps": 3,
                "weights": str(tmp_path / name / "w.msgpack"), "val_batch_size": 32},
    })


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return _tiny_traffic.write(tmp_path_factory.mktemp("traffic") / "ds")


def test_resume_equals_uninterrupted(tmp_path, data):
    maneuvers = True  # the variant with every loss term (NLL + both class losses)
    # NLL epochs only: one compiled step (the MSE step is exercised by the single-mode test).
    # The cosine schedule: its position must survive the interruption too.
    full_cfg = _cfg(tmp_path, data, "full", maneuvers, mse_epochs=0, nll_epochs=2, schedule="cosine")
    card = train(full_cfg, progress=False, log=lambda _: None)
    part_cfg = _cfg(tmp_path, data, "part", maneuvers, mse_epochs=0, nll_epochs=2, schedule="cosine")
    assert train(part_cfg, progress=False, stop_after_steps=5) == {}  # interrupted after step 5
    assert not (tmp_path / "part" / "w.msgpack").exists()
    # Resumes from the checkpoint of step 3, in the middle of the first epoch (4 steps each).
    resumed = train(part_cfg, resume=True, progress=False, log=lambda _: None)
    a = state_dict_from_model(load_weights(tmp_path / "full" / "w.msgpack"))
    b = state_dict_from_model(load_weights(tmp_path / "part" / "w.msgpack"))
    for key in a:
        assert np.array_equal(a[key], b[key]), key
    assert resumed["history"] == card["history"]
    assert resumed["validation"] == card["validation"]
    # The card: steps, data, per-second RMSE of the network and of constant velocity.
    assert card["steps"] == 2 * (72 // 16) and card["maneuvers"] is maneuvers
    assert card["data"]["num_train_samples"] == 72 and card["data"]["num_val_samples"] == 24
    assert len(card["validation"]["rmse_m"]["cslstm"]) == 5
    assert len(card["validation"]["rmse_m"]["constant_velocity"]) == 5
    axes = card["validation"]["rmse_by_axis_m"]["cslstm"]
    np.testing.assert_allclose(np.hypot(axes["lon"], axes["lat"]), card["validation"]["rmse_m"]["cslstm"], atol=2e-4)
    assert all(np.isfinite(card["validation"]["rmse_m"]["cslstm"]))
    assert read_card(tmp_path / "full" / "w.msgpack") == card
    assert (tmp_path / "full" / "w.msgpack").stat().st_size < 2_000_000
    # The weights serve the SI predictor directly.
    predictor = load_predictor(tmp_path / "full" / "w.msgpack")
    samples, _ = load_samples(data)
    out = jax.jit(predict_mean)(predictor, samples.hist_m[:4], np.zeros((4, 1, 16, 2), np.float32),
                                np.full((4, 1), -1, np.int32), np.zeros((4, 1), np.float32))
    assert out.shape == (4, 25, 2) and out.dtype == jnp.float32


def test_single_mode_trains_and_resume_needs_a_checkpoint(tmp_path, data):
    with pytest.raises(InputError, match="no checkpoint"):
        train(_cfg(tmp_path, data, "none"), resume=True, progress=False)
    # MSE in the scaled units with a lateral scale of its own (the default recipe's options).
    card = train(_cfg(tmp_path, data, "single", mse_epochs=1, nll_epochs=0, position_scale_ft=100.0,
                      lateral_scale_ft=20.0, mse_in_scaled_units=True), progress=False)
    assert card["maneuvers"] is False and card["steps"] == 72 // 16
    assert all(np.isfinite(card["validation"]["rmse_m"]["cslstm"]))


def test_samples_are_converted_to_the_model_frame(data):
    samples, meta = load_samples(data)
    assert len(samples) == 96 and meta["config"] == {"tiny": True}
    np.testing.assert_allclose(samples.hist[..., 1], samples.hist_m[..., 0] / 0.3048, rtol=1e-6)
    np.testing.assert_allclose(samples.hist[..., 0], -samples.hist_m[..., 1] / 0.3048, rtol=1e-6, atol=1e-6)
    present = samples.nbr_weight > 0
    assert np.all(samples.nbr_slot[present] >= 0) and np.all(samples.nbr_slot[~present] == -1)


def test_metrics_and_constant_velocity():
    t = 0.2 * np.arange(-15, 1)
    hist = np.stack([25.0 * t, 0.5 * t], -1)[None]
    fut_cv = constant_velocity_m(hist, 2)
    np.testing.assert_allclose(fut_cv[0, 4], [25.0, 0.5], atol=1e-12)  # 1 s ahead
    np.testing.assert_allclose(rmse_per_second(fut_cv, fut_cv), np.zeros(5))
    shifted = fut_cv + np.array([3.0, 4.0])
    np.testing.assert_allclose(rmse_per_second(shifted, fut_cv), np.full(5, 5.0))
    from diffsense.train._metrics import rmse_per_second_by_axis

    assert rmse_per_second_by_axis(shifted, fut_cv) == {"lon": [3.0] * 5, "lat": [4.0] * 5}


_nll_grad, _mse_grad, _bce_grad = (jax.jit(jax.value_and_grad(f)) for f in (nll, mse, class_bce))


def test_losses_finite_and_gradients_at_extremes():
    fut = jnp.ones((2, 25, 2))
    for scale in (0.0, 1e3):
        raw = jnp.full((2, 25, 5), scale)
        logits = jnp.array([[scale, -scale, 0.0], [0.0, 0.0, 0.0]])
        label = jnp.array([1, 2])
        for fn, args in ((_nll_grad, (raw, fut)), (_mse_grad, (raw, fut)), (_bce_grad, (logits, label))):
            value, grad = fn(*args)
            assert np.isfinite(value) and np.all(np.isfinite(grad))
    # NLL equals the closed form of the bivariate Gaussian density at moderate values.
    raw = jnp.array([[[0.3, -0.2, np.log(2.0), np.log(0.5), np.arctanh(0.3)]]])
    y = jnp.array([[[1.0, 0.5]]])
    sx, sy, rho = 0.5, 2.0, 0.3  # standard deviations are the inverses of exp(raw)
    dx, dy = 0.7, 0.7
    z = dx**2 / sx**2 + dy**2 / sy**2 - 2 * rho * dx * dy / (sx * sy)
    want = z / (2 * (1 - rho**2)) + np.log(2 * np.pi * sx * sy * np.sqrt(1 - rho**2))
    np.testing.assert_allclose(nll(raw, y), want, rtol=1e-6)


def test_cli_bad_config_is_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('maneuvers = false\n[data]\npath = "x"\nvall_fraction = 0.1\n')
    proc = subprocess.run([sys.executable, "-m", "diffsense.train", "--config", str(bad)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "unknown key 'data.vall_fraction'" in proc.stderr
    assert proc.stderr.strip().count("\n") == 0
    good_paths = tmp_path / "nodata.toml"
    good_paths.write_text(f'[data]\npath = "{tmp_path / "absent"}"\n')
    proc = subprocess.run([sys.executable, "-m", "diffsense.train", "--config", str(good_paths)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "not a traffic dataset" in proc.stderr, proc.stderr
    assert proc.stderr.strip().count("\n") == 0


def test_mse_in_scaled_units_weighs_each_axis_in_its_own_unit(data):
    from flax import nnx

    from diffsense.predictors._model import new_model
    from diffsense.train._config import OptimConfig
    from diffsense.train._loop import _make_step

    samples, _ = load_samples(data)
    batch = tuple(np.asarray(x[:8]) for x in (samples.hist, samples.fut, samples.nbr_hist, samples.nbr_slot,
                                              samples.nbr_weight, samples.lat, samples.lon))
    graphdef, params = nnx.split(new_model(False, 0))
    feet = OptimConfig(position_scale_ft=100.0, lateral_scale_ft=20.0)
    scaled = dataclasses.replace(feet, mse_in_scaled_units=True)
    from diffsense.train._loop import _optimiser

    losses = {}
    for name, optim in (("feet", feet), ("scaled", scaled)):
        step = _make_step(graphdef, optim, 10, False)
        losses[name] = float(step(params, _optimiser(optim, 10).init(params), batch, False)[2])
    # The same network output: the scaled loss is the feet loss with each axis divided by its
    # scale squared, so it lies between the two bounds.
    assert losses["feet"] / 100.0**2 < losses["scaled"] < losses["feet"] / 20.0**2


def test_learning_rate_schedules():
    from diffsense.train._config import OptimConfig
    from diffsense.train._loop import _optimiser

    def lr_at(optim: OptimConfig, step: int, total: int) -> float:
        """The size of update number `step` under a constant unit gradient: Adam's normalised
        moment is then 1 (to eps), so the update is the learning rate itself."""
        tx = _optimiser(optim, total)
        state = tx.init(jnp.zeros(()))
        for _ in range(step + 1):
            update, state = tx.update(jnp.ones(()), state)
        return -float(update)

    assert lr_at(OptimConfig(), 0, 20) == pytest.approx(1e-3, rel=1e-5)
    assert lr_at(OptimConfig(), 20, 20) == pytest.approx(1e-3, rel=1e-5)
    cosine = OptimConfig(schedule="cosine", final_lr_fraction=0.01)
    assert lr_at(cosine, 0, 20) == pytest.approx(1e-3, rel=1e-5)
    assert lr_at(cosine, 10, 20) == pytest.approx(1e-3 * (0.01 + 0.99 * 0.5), rel=1e-5)
    assert lr_at(cosine, 20, 20) == pytest.approx(1e-5, rel=1e-4)
    with pytest.raises(InputError, match="optim.schedule"):
        OptimConfig(schedule="linear")
    with pytest.raises(InputError, match="final_lr_fraction"):
        OptimConfig(final_lr_fraction=2.0)


def test_shipped_default_config_loads():
    from diffsense.config import load_default

    cfg = load_default(TrainConfig, "train/default.toml")
    assert dataclasses.asdict(cfg.optim)["learning_rate"] == 1e-3 and cfg.optim.batch_size == 128
    from diffsense.train._loop import position_scale

    np.testing.assert_array_equal(position_scale(cfg.optim), [cfg.optim.lateral_scale_ft, cfg.optim.position_scale_ft])
    one = dataclasses.replace(cfg.optim, lateral_scale_ft=0.0)
    np.testing.assert_array_equal(position_scale(one), [cfg.optim.position_scale_ft] * 2)


def test_position_scale_folds_exactly_into_the_plain_network():
    from flax import nnx

    from diffsense.predictors._model import model_from_params, param_shapes
    from diffsense.train._loop import fold_position_scale

    rng = np.random.default_rng(1)
    shapes = param_shapes(False)
    arrays = {k: {kk: rng.uniform(-0.3, 0.3, size=vv) for kk, vv in v.items()} for k, v in shapes.items()}
    graphdef, params = nnx.split(model_from_params(False, arrays))
    scale = np.array([7.5, 75.0])  # per model-frame component (lateral, longitudinal)
    trained, folded = nnx.merge(graphdef, params), nnx.merge(graphdef, fold_position_scale(params, scale))
    rng = np.random.default_rng(0)
    x, h = rng.normal(size=(4, 2)) * 100, rng.normal(size=(4, 128))
    # The only layers that see positions: the input embedding and the two mean outputs.
    np.testing.assert_allclose(folded.ip_emb(x), trained.ip_emb(x / scale), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(folded.op(h)[:, :2], scale * trained.op(h)[:, :2], rtol=1e-12, atol=1e-10)
    np.testing.assert_allclose(folded.op(h)[:, 2:], trained.op(h)[:, 2:], rtol=1e-12, atol=1e-12)
    same = jax.tree.map(lambda a, b: bool(np.array_equal(a, b)), nnx.state(trained.enc_lstm), nnx.state(folded.enc_lstm))
    assert all(jax.tree.leaves(same))
