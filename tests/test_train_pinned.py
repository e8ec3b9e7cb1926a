"""The training's losses, validation metrics and config pinned against independent values: the
bivariate Gaussian NLL against numpy's covariance-matrix log density, BCE against softmax
probabilities, the caps by where their gradient stops, the per-second RMSE and the
constant-velocity baseline by hand, and every config refusal by its whole message."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.runtime._errors import InputError
from diffsense.train import TrainConfig, constant_velocity_m, rmse_per_second
from diffsense.train._config import DataConfig, OptimConfig, RunConfig
from diffsense.train._loss import _log_cosh, class_bce, mse, nll
from diffsense.train._metrics import DT_S, SECOND_INDEX, rmse_per_second_by_axis


@pytest.fixture(autouse=True, scope="module")
def _x64():
    jax.config.update("jax_enable_x64", True)


def _raw_and_future(seed: int = 0):
    rng = np.random.default_rng(seed)
    raw = np.concatenate([rng.normal(0.0, 2.0, (3, 25, 2)), rng.normal(0.0, 1.0, (3, 25, 2)),
                          rng.normal(0.0, 0.8, (3, 25, 1))], axis=-1)
    return raw, rng.normal(0.0, 2.0, (3, 25, 2))


def _neg_log_density(raw: np.ndarray, fut: np.ndarray) -> float:
    """-log N(fut; mu, Sigma) per point from the covariance matrix, averaged."""
    out = []
    for r, y in zip(raw.reshape(-1, 5), fut.reshape(-1, 2)):
        sx, sy, rho = 1.0 / np.exp(r[2]), 1.0 / np.exp(r[3]), np.tanh(r[4])
        cov = np.array([[sx**2, rho * sx * sy], [rho * sx * sy, sy**2]])
        d = y - r[:2]
        out.append(0.5 * d @ np.linalg.solve(cov, d) + 0.5 * np.log(np.linalg.det(2 * np.pi * cov)))
    return float(np.mean(out))


def test_nll_is_the_bivariate_gaussians_negative_log_density():
    raw, fut = _raw_and_future()
    np.testing.assert_allclose(float(nll(jnp.asarray(raw), jnp.asarray(fut))), _neg_log_density(raw, fut),
                               rtol=1e-12)


def test_mse_is_the_mean_squared_distance_per_point():
    raw, fut = _raw_and_future(1)
    by_hand = np.mean([np.sum((raw[b, t, :2] - fut[b, t]) ** 2) for b in range(3) for t in range(25)])
    np.testing.assert_allclose(float(mse(jnp.asarray(raw), jnp.asarray(fut))), by_hand, rtol=1e-12)


def test_log_cosh_without_overflow():
    z = np.linspace(-30.0, 30.0, 121)
    np.testing.assert_allclose(np.asarray(_log_cosh(jnp.asarray(z))), np.log(np.cosh(z)), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(float(_log_cosh(jnp.asarray(800.0))), 800.0 - np.log(2.0), rtol=1e-15)


@pytest.mark.parametrize(("column", "cap"), [(4, 15.0), (2, 20.0), (3, 20.0)])
def test_the_caps_hold_the_value_and_stop_the_gradient(column, cap):
    raw, fut = _raw_and_future(2)
    raw, fut = raw[:1, :1], fut[:1, :1]
    grad = jax.grad(lambda r: nll(r, jnp.asarray(fut)))
    for sign in (1.0, -1.0):
        at_cap, beyond = raw.copy(), raw.copy()
        at_cap[..., column], beyond[..., column] = sign * cap, sign * (cap + 5.0)
        value = float(nll(jnp.asarray(beyond), jnp.asarray(fut)))
        assert np.isfinite(value) and value == float(nll(jnp.asarray(at_cap), jnp.asarray(fut)))
        assert float(grad(jnp.asarray(beyond))[..., column].item()) == 0.0
        inside = raw.copy()
        inside[..., column] = sign * (cap - 1.0)
        assert float(grad(jnp.asarray(inside))[..., column].item()) != 0.0


def test_class_bce_is_torchs_bce_of_softmax_probabilities():
    logits = np.array([[2.0, -1.0, 0.5], [0.0, 0.0, 0.0], [-3.0, 4.0, 1.0], [1.0, 1.5, -0.5]])  # B 4, C 3
    label = np.array([0, 2, 1, 1])
    p = np.exp(logits) / np.exp(logits).sum(axis=1, keepdims=True)
    onehot = np.eye(3)[label]
    by_hand = -np.mean(onehot * np.log(p) + (1 - onehot) * np.log(1 - p))
    np.testing.assert_allclose(float(class_bce(jnp.asarray(logits), jnp.asarray(label))), by_hand, rtol=1e-12)
    assert class_bce(jnp.asarray(logits, jnp.float32), jnp.asarray(label)).dtype == jnp.float32  # the logits' own
    two = np.array([[1.0, -1.0]])
    q = 1.0 / (1.0 + np.exp(-2.0))  # softmax of two logits 2 apart
    np.testing.assert_allclose(float(class_bce(jnp.asarray(two), jnp.asarray([1]))), -np.log(1 - q), rtol=1e-12)


def test_rmse_is_taken_at_each_whole_second():
    assert DT_S == 0.2 and list(SECOND_INDEX) == [4, 9, 14, 19, 24]
    fut = np.full((2, 25, 2), 10.0)
    pred = fut.copy()
    pred[:, 3] += 7.0  # 0.8 s: not a whole second
    pred[0, 9] += [3.0, 4.0]  # 2 s, one of two samples: sqrt(25 / 2)
    pred[:, 24, 1] -= 2.0  # 5 s, both samples, lateral only
    np.testing.assert_allclose(rmse_per_second(pred, fut), [0.0, np.sqrt(12.5), 0.0, 0.0, 2.0], rtol=1e-15)
    by_axis = rmse_per_second_by_axis(pred, fut)
    assert by_axis == {"lon": [0.0, round(np.sqrt(4.5), 4), 0.0, 0.0, 0.0],
                       "lat": [0.0, round(np.sqrt(8.0), 4), 0.0, 0.0, 2.0]}
    assert rmse_per_second_by_axis(fut + 1.0 / 3.0, fut)["lon"] == [0.3333] * 5
    small = np.float32(0.1) * np.ones((1, 25, 2), np.float32)  # float32 in, squared in float64
    np.testing.assert_array_equal(rmse_per_second(small, 0 * small), np.full(5, np.sqrt(2 * float(small[0, 0, 0]) ** 2)))


def test_constant_velocity_from_the_last_points():
    hist = np.array([[[-1.0, 9.0], [0.0, 0.0], [1.0, 0.0], [2.0, 0.5]]])
    two = constant_velocity_m(hist, 2)  # (1, 0.5) m in 0.2 s: (5, 2.5) m/s
    np.testing.assert_allclose(two[0, 0], [3.0, 1.0], rtol=1e-12)
    np.testing.assert_allclose(two[0, 24], [2.0 + 5.0 * 5.0, 0.5 + 2.5 * 5.0], rtol=1e-12)
    three = constant_velocity_m(hist, 3)  # (2, 0.5) m in 0.4 s
    np.testing.assert_allclose(three[0, 4], [2.0 + 5.0, 0.5 + 1.25], rtol=1e-12)
    assert two.shape == (1, 25, 2)
    thirds = constant_velocity_m(np.asarray(hist / 3.0, np.float32), 2)  # float32 in, float64 out
    assert thirds.dtype == np.float64
    np.testing.assert_array_equal(thirds, constant_velocity_m(np.asarray(hist / 3.0, np.float32).astype(np.float64), 2))


@pytest.mark.parametrize(("cls", "field", "value", "message"), [
    (DataConfig, "val_fraction", 0.0, "data.val_fraction must be in (0, 1), got 0.0"),
    (DataConfig, "val_fraction", 1.0, "data.val_fraction must be in (0, 1), got 1.0"),
    (DataConfig, "max_samples", -1, "data.max_samples must be >= 0, got -1"),
    (DataConfig, "cv_points", 1, "data.cv_points must be in 2..16, got 1"),
    (DataConfig, "cv_points", 17, "data.cv_points must be in 2..16, got 17"),
    (OptimConfig, "schedule", "linear", "optim.schedule must be 'constant' or 'cosine', got 'linear'"),
    (OptimConfig, "final_lr_fraction", -0.01, "optim.final_lr_fraction must be in [0, 1], got -0.01"),
    (OptimConfig, "final_lr_fraction", 1.01, "optim.final_lr_fraction must be in [0, 1], got 1.01"),
    (OptimConfig, "position_scale_ft", 0.0, "optim.position_scale_ft must be > 0, got 0.0"),
    (OptimConfig, "lateral_scale_ft", -0.5, "optim.lateral_scale_ft must be >= 0, got -0.5"),
    (OptimConfig, "learning_rate", 0.0, "optim.learning_rate must be > 0, got 0.0"),
    (OptimConfig, "batch_size", 0, "optim.batch_size must be >= 1, got 0"),
    (OptimConfig, "clip_grad_norm", 0.0, "optim.clip_grad_norm must be > 0, got 0.0"),
    (OptimConfig, "mse_epochs", -1, "optim.mse_epochs and optim.nll_epochs must be >= 0 with at least one epoch"),
    (OptimConfig, "nll_epochs", -1, "optim.mse_epochs and optim.nll_epochs must be >= 0 with at least one epoch"),
    (RunConfig, "checkpoint_every_steps", 0, "run.checkpoint_every_steps must be >= 1, got 0"),
    (RunConfig, "val_batch_size", 0, "run.val_batch_size must be >= 1, got 0"),
])
def test_config_refusals_by_whole_message(cls, field, value, message):
    base = {"path": "d"} if cls is DataConfig else {}
    if field in ("mse_epochs", "nll_epochs"):
        base = {"mse_epochs": 4, "nll_epochs": 4}
    with pytest.raises(InputError) as err:
        cls(**{**base, field: value})
    assert str(err.value) == message


def test_config_edges_and_defaults_that_are_accepted():
    DataConfig(path="d", val_fraction=0.999, max_samples=0, cv_points=2)
    DataConfig(path="d", val_fraction=0.001, cv_points=16)
    OptimConfig(final_lr_fraction=0.0, lateral_scale_ft=0.0, batch_size=1, schedule="cosine")
    OptimConfig(final_lr_fraction=1.0)
    OptimConfig(mse_epochs=1, nll_epochs=0)
    OptimConfig(mse_epochs=0, nll_epochs=1)
    with pytest.raises(InputError):
        OptimConfig(mse_epochs=0, nll_epochs=0)
    RunConfig(checkpoint_every_steps=1, val_batch_size=1)
    OptimConfig(clip_grad_norm=0.5, learning_rate=1e-9, position_scale_ft=0.5)
    assert dataclasses.asdict(OptimConfig()) == {
        "learning_rate": 1e-3, "batch_size": 128, "clip_grad_norm": 10.0, "mse_epochs": 5, "nll_epochs": 3,
        "seed": 0, "position_scale_ft": 1.0, "lateral_scale_ft": 0.0, "mse_in_scaled_units": False,
        "schedule": "constant", "final_lr_fraction": 0.01}
    assert dataclasses.asdict(DataConfig(path="d")) == {"path": "d", "val_fraction": 0.1, "max_samples": 0,
                                                        "cv_points": 2}
    assert dataclasses.asdict(RunConfig()) == {"checkpoint_dir": "runs/train", "checkpoint_every_steps": 200,
                                               "weights": "diffsense/predictors/weights/cslstm.msgpack",
                                               "val_batch_size": 512}
    cfg = TrainConfig(data=DataConfig(path="d"))
    assert cfg.maneuvers is False and cfg.optim == OptimConfig() and cfg.run == RunConfig()
