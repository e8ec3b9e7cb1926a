"""The CS-LSTM module's constructors and entry points beyond the numpy parity of
`test_predict.py`: the variant each constructor builds, the dense call against the compact one,
float32 kept through both, the mean trajectory of each mode, histories with any leading axes,
the compact input's padding and shared slots, and the refused mean mode."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import nnx

from diffsense.predictors._model import (
    CSLSTM,
    N_SLOTS,
    model_from_params,
    new_model,
    param_shapes,
)

B, N = 3, 4


def _shapes(model: CSLSTM) -> dict:
    return jax.tree.map(lambda a: tuple(a.shape), nnx.to_pure_dict(nnx.state(model, nnx.Param)))


def _wide_model(maneuvers: bool, seed: int = 0, dtype=np.float64) -> CSLSTM:
    """Parameters uniform in [-0.5, 0.5], wider than the initialisation, so every layer shows."""
    rng = np.random.default_rng(seed)
    params = jax.tree.map(lambda shape: rng.uniform(-0.5, 0.5, size=shape).astype(dtype), param_shapes(maneuvers),
                          is_leaf=lambda x: isinstance(x, tuple))
    return model_from_params(maneuvers, params)


def _batch(seed: int):
    """Model-frame histories [ft] of B targets with N neighbours each, in distinct slots."""
    rng = np.random.default_rng(seed)
    hist = jnp.asarray(rng.normal(size=(B, 16, 2)) * [3.0, 40.0])
    nbr_hist = jnp.asarray(rng.normal(size=(B, N, 16, 2)) * [12.0, 60.0])
    slot = jnp.asarray(np.stack([rng.choice(N_SLOTS, N, replace=False) for _ in range(B)]), jnp.int32)
    weight = jnp.asarray(rng.uniform(0.2, 1.0, size=(B, N)))
    return hist, nbr_hist, slot, weight


def _assert_same_prediction(got, want):
    for name in ("fut", "mode_prob", "lat_prob", "lon_prob"):
        a, b = getattr(got, name), getattr(want, name)
        if b is None:
            assert a is None, name
        else:
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12, err_msg=name)


def test_the_module_is_the_single_mode_variant_unless_asked():
    model = nnx.eval_shape(lambda: CSLSTM(rngs=nnx.Rngs(0)))
    assert model.maneuvers is False
    assert _shapes(model) == param_shapes(False)
    assert param_shapes(False)["dec_lstm"]["w_ih"] == (112, 512)  # social 80 + dynamics 32
    assert param_shapes(True)["dec_lstm"]["w_ih"] == (117, 512)  # + 3 lateral + 2 longitudinal


@pytest.mark.parametrize("maneuvers", [False, True])
def test_new_model_builds_the_variant_asked_for_from_its_seed(maneuvers):
    model = new_model(maneuvers, 3)
    assert model.maneuvers is maneuvers
    assert _shapes(model) == param_shapes(maneuvers)
    again, other = nnx.state(new_model(maneuvers, 3), nnx.Param), nnx.state(new_model(maneuvers, 4), nnx.Param)
    for a, b, c in zip(jax.tree.leaves(nnx.state(model, nnx.Param)), jax.tree.leaves(again), jax.tree.leaves(other)):
        np.testing.assert_array_equal(a, b)
        assert not np.array_equal(a, c)  # every parameter, biases too, is drawn from the seed


@pytest.mark.parametrize("maneuvers", [False, True])
def test_the_dense_call_is_the_compact_call_with_each_neighbour_in_its_slot(maneuvers):
    model = _wide_model(maneuvers)
    hist, nbr_hist, slot, weight = _batch(1)
    slot = slot.at[0].set(jnp.asarray([0, N_SLOTS - 1, 7, 30], jnp.int32))  # the grid's first and last slots
    rows = jnp.arange(B)[:, None]
    nbrs = jnp.zeros((B, N_SLOTS, 16, 2)).at[rows, slot].set(nbr_hist)
    occupancy = jnp.zeros((B, N_SLOTS)).at[rows, slot].set(weight)
    dense = model(hist, nbrs, occupancy)
    compact = model.compact(hist, nbr_hist, slot, weight)
    _assert_same_prediction(dense, compact)
    k = 6 if maneuvers else 1
    assert dense.fut.shape == (B, k, 25, 5) and dense.mode_prob.shape == (B, k)
    if maneuvers:
        np.testing.assert_allclose(dense.mode_prob.sum(-1), 1.0, rtol=1e-12)


@pytest.mark.parametrize("maneuvers", [False, True])
def test_a_float32_network_answers_in_float32_through_both_entry_points(maneuvers):
    model = _wide_model(maneuvers, dtype=np.float32)
    hist, nbr_hist, slot, weight = (a.astype(jnp.float32) if a.dtype != jnp.int32 else a for a in _batch(4))
    rows = jnp.arange(B)[:, None]
    nbrs = jnp.zeros((B, N_SLOTS, 16, 2), jnp.float32).at[rows, slot].set(nbr_hist)
    occupancy = jnp.zeros((B, N_SLOTS), jnp.float32).at[rows, slot].set(weight)
    for pred in (model(hist, nbrs, occupancy), model.compact(hist, nbr_hist, slot, weight)):
        fields = [pred.fut, pred.mode_prob] + ([pred.lat_prob, pred.lon_prob] if maneuvers else [])
        assert [f.dtype for f in fields] == [jnp.float32] * len(fields)


def test_histories_are_encoded_with_any_leading_axes():
    model = _wide_model(False)
    xy = jnp.asarray(np.random.default_rng(5).normal(size=(2, 3, 16, 2)))
    enc = model.encode_tracks(xy)
    assert enc.shape == (2, 3, 64)
    np.testing.assert_allclose(model.encode_tracks(xy.reshape(6, 16, 2)), enc.reshape(6, 64), rtol=1e-12)
    np.testing.assert_allclose(model.encode_tracks(xy[None]), enc[None], rtol=1e-12)


def test_compact_input_ignores_slots_outside_the_grid_and_adds_neighbours_sharing_one():
    model = _wide_model(True, seed=2)
    hist, nbr_hist, slot, weight = _batch(3)
    want = model.compact(hist, nbr_hist, slot, weight)
    # Padding: four more neighbours per row, in slots -1, -5, 39 and 40, with histories and
    # weights of their own, change nothing.
    outside = jnp.asarray([[-1, -5, N_SLOTS, N_SLOTS + 1]], jnp.int32)
    pad_hist = jnp.concatenate([nbr_hist, 5.0 + nbr_hist], axis=1)
    pad_slot = jnp.concatenate([slot, jnp.tile(outside, (B, 1))], axis=1)
    pad_weight = jnp.concatenate([weight, jnp.ones((B, N))], axis=1)
    _assert_same_prediction(model.compact(hist, pad_hist, pad_slot, pad_weight), want)
    # Shared slot: the first neighbour given twice, its weight split 30 / 70, is the one neighbour.
    split_hist = jnp.concatenate([nbr_hist[:, :1], nbr_hist], axis=1)
    split_slot = jnp.concatenate([slot[:, :1], slot], axis=1)
    split_weight = jnp.concatenate([0.3 * weight[:, :1], weight.at[:, 0].multiply(0.7)], axis=1)
    _assert_same_prediction(model.compact(hist, split_hist, split_slot, split_weight), want)


@pytest.mark.parametrize("dtype, tol", [(np.float64, 1e-12), (np.float32, 1e-5)])
def test_the_mean_trajectory_is_the_most_probable_mode_or_the_probability_weighted_one(dtype, tol):
    model = _wide_model(True, seed=6, dtype=dtype)
    enc = jnp.asarray(np.random.default_rng(7).normal(size=(64, 112)) * 2.0, dtype)
    pred = model.heads(enc)
    lat, lon = np.asarray(pred.lat_prob, np.float64), np.asarray(pred.lon_prob, np.float64)
    # mode = lon * 3 + lat, its probability the product of the two
    np.testing.assert_allclose(pred.mode_prob, (lon[:, :, None] * lat[:, None, :]).reshape(64, 6), rtol=tol)
    fut = np.asarray(pred.fut[..., :2], np.float64)
    picked = fut[np.arange(64), lon.argmax(-1) * 3 + lat.argmax(-1)]
    weighted = np.einsum("bk,bktc->btc", np.asarray(pred.mode_prob, np.float64), fut)
    for mean, want in ((model.mean_from_context(enc), picked),
                       (model.mean_from_context(enc, mode="most_probable"), picked),
                       (model.mean_from_context(enc, mode="weighted"), weighted)):
        assert mean.shape == (64, 25, 2) and mean.dtype == dtype
        np.testing.assert_allclose(mean, want, rtol=tol, atol=tol)
    single = _wide_model(False, seed=6, dtype=dtype)
    mean = single.mean_from_context(enc)
    assert mean.shape == (64, 25, 2) and mean.dtype == dtype
    np.testing.assert_allclose(mean, single.heads(enc).fut[:, 0, :, :2], rtol=tol, atol=tol)


def test_an_unknown_mean_mode_is_refused_by_name():
    model = _wide_model(True)
    enc = jnp.zeros((B, 112))
    with pytest.raises(ValueError, match=r"^mode must be 'most_probable' or 'weighted', got 'mean'$"):
        model.mean_from_context(enc, mode="mean")
