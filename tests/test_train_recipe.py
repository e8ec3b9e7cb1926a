"""The training recipe against independent values: the bivariate Gaussian NLL against numpy's
covariance-matrix log density, BCE against softmax probabilities, the caps by where their gradient
stops, the per-second RMSE and the constant-velocity baseline by hand, the learning-rate
schedules, the position scale folded exactly into a plain network, the config's defaults and
every refusal by the field it names."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import nnx

from diffsense.config import load_default
from diffsense.predictors import init_predictor
from diffsense.runtime import InputError
from diffsense.train import (
    DataConfig,
    OptimConfig,
    RunConfig,
    TrainConfig,
    class_bce,
    constant_velocity_m,
    fold_position_scale,
    mse,
    nll,
    position_scale,
    rmse_per_second,
    rmse_per_second_by_axis,
)
from diffsense.train._loop import (
    _optimiser,  # the recipe's optimiser: what the schedules are is under test
)


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


def test_losses_and_their_gradients_are_finite_at_extremes():
    fut = jnp.ones((2, 25, 2))
    for scale in (0.0, 1e3):
        raw = jnp.full((2, 25, 5), scale)
        logits = jnp.array([[scale, -scale, 0.0], [0.0, 0.0, 0.0]])
        for fn, args in ((nll, (raw, fut)), (mse, (raw, fut)), (class_bce, (logits, jnp.array([1, 2])))):
            value, grad = jax.value_and_grad(fn)(*args)
            assert np.isfinite(value) and np.all(np.isfinite(grad))


def test_rmse_is_taken_at_each_whole_second():
    # The future's points are 0.2 s apart: the whole seconds are points 4, 9, 14, 19 and 24.
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


@pytest.mark.parametrize(("cls", "field", "value"), [
    (DataConfig, "val_fraction", 0.0), (DataConfig, "val_fraction", 1.0), (DataConfig, "max_samples", -1),
    (DataConfig, "cv_points", 1), (DataConfig, "cv_points", 17), (OptimConfig, "schedule", "linear"),
    (OptimConfig, "final_lr_fraction", -0.01), (OptimConfig, "final_lr_fraction", 1.01),
    (OptimConfig, "position_scale_ft", 0.0), (OptimConfig, "lateral_scale_ft", -0.5),
    (OptimConfig, "learning_rate", 0.0), (OptimConfig, "batch_size", 0), (OptimConfig, "clip_grad_norm", 0.0),
    (OptimConfig, "mse_epochs", -1), (OptimConfig, "nll_epochs", -1), (RunConfig, "checkpoint_every_steps", 0),
    (RunConfig, "val_batch_size", 0),
])
def test_config_refusals_name_the_field(cls, field, value):
    base = {"path": "d"} if cls is DataConfig else {}
    if field in ("mse_epochs", "nll_epochs"):
        base = {"mse_epochs": 4, "nll_epochs": 4}
    section = {DataConfig: "data", OptimConfig: "optim", RunConfig: "run"}[cls]
    with pytest.raises(InputError, match=f"{section}.{field}"):
        cls(**{**base, field: value})


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


def test_the_shipped_default_config_loads():
    cfg = load_default(TrainConfig, "train/default.toml")
    assert cfg.optim.learning_rate == 1e-3 and cfg.optim.batch_size == 128


def test_position_scale_is_lateral_then_longitudinal():
    np.testing.assert_array_equal(position_scale(OptimConfig(position_scale_ft=100.0)), [100.0, 100.0])
    np.testing.assert_array_equal(position_scale(OptimConfig(position_scale_ft=100.0, lateral_scale_ft=20.0)),
                                  [20.0, 100.0])


def test_position_scale_folds_exactly_into_the_plain_network():
    graphdef, params = nnx.split(init_predictor(seed=1).model(jnp.float64))
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


def _lr_at(optim: OptimConfig, step: int, total: int) -> float:
    """The size of update number `step` under a constant unit gradient: Adam's normalised moment
    is then 1 (to eps), so the update is the learning rate itself."""
    tx = _optimiser(optim, total)
    state = tx.init(jnp.zeros(()))
    for _ in range(step + 1):
        update, state = tx.update(jnp.ones(()), state)
    return -float(update)


def test_learning_rate_schedules():
    assert _lr_at(OptimConfig(), 0, 20) == pytest.approx(1e-3, rel=1e-5)
    assert _lr_at(OptimConfig(), 20, 20) == pytest.approx(1e-3, rel=1e-5)
    cosine = OptimConfig(schedule="cosine", final_lr_fraction=0.01)
    assert _lr_at(cosine, 0, 20) == pytest.approx(1e-3, rel=1e-5)
    assert _lr_at(cosine, 10, 20) == pytest.approx(1e-3 * (0.01 + 0.99 * 0.5), rel=1e-5)
    assert _lr_at(cosine, 20, 20) == pytest.approx(1e-5, rel=1e-4)
