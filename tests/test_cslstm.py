"""The CS-LSTM against an independent numpy forward (random wide weights and the published
checkpoints), its dense and compact inputs, padding and occupancy, the mean of each mode, float32
kept, and gradients against central differences in float64."""

from __future__ import annotations

import _numpy_cslstm
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.predictors import (
    N_SLOTS,
    CSLSTMPredictor,
    init_predictor,
    load_predictor,
    model_from_state_dict,
    model_to_si,
    predict_mean,
    predict_mean_dense,
    predict_model_frame,
    read_state_dict,
    reference_forward,
    reference_to_compact,
    select_mean,
    si_to_model,
    state_dict_from_model,
)

B, N = 3, 4
VARIANTS = pytest.mark.parametrize("maneuvers", [False, True], ids=["single", "maneuver"])
# One jitted function per entry point; the predictor is an argument (a closed-over predictor would
# become an XLA constant, constant-folded at great compile cost).
_frame = jax.jit(predict_model_frame)
_mean = jax.jit(predict_mean, static_argnames="mode")
_mean_dense = jax.jit(predict_mean_dense, static_argnames="mode")


def _wide_state_dict(maneuvers: bool, seed: int = 0) -> dict[str, np.ndarray]:
    """Weights uniform in [-0.5, 0.5], wider than PyTorch's initialisation, so every layer shows."""
    rng = np.random.default_rng(seed)
    shapes = state_dict_from_model(init_predictor(maneuvers).model())
    return {k: rng.uniform(-0.5, 0.5, v.shape).astype(np.float32) for k, v in shapes.items()}


@pytest.fixture(scope="module")
def networks():
    """{maneuvers: (predictor, its state_dict)}."""
    sds = {m: _wide_state_dict(m) for m in (False, True)}
    return {m: (CSLSTMPredictor.from_model(model_from_state_dict(sd)), sd) for m, sd in sds.items()}


def _reference_batch(rng: np.random.Generator, b: int = B):
    """A batch in the reference layout: model frame (ft), up to N neighbours per sample."""
    mask = np.zeros((b, 3, 13, 64), bool)
    for row in range(b):
        slots = rng.choice([s for s in range(39) if s != 19], size=N - row % 2, replace=False)
        mask[row].reshape(39, 64)[slots] = True
    n = int(mask[..., 0].sum())
    hist = (rng.normal(size=(16, b, 2)) * [3.0, 40.0]).astype(np.float32)
    nbrs = (rng.normal(size=(16, n, 2)) * [12.0, 60.0]).astype(np.float32)
    return hist, nbrs, mask


def _compare_with_numpy(predictor, sd, hist, nbrs, mask, rtol, atol):
    inputs = [np.asarray(a, np.float64) if a.dtype.kind == "f" else a for a in reference_to_compact(hist, nbrs, mask)]
    pred = _frame(predictor, *inputs)
    want = _numpy_cslstm.forward(sd, hist, nbrs, mask)
    fut = np.asarray(pred.fut).transpose(1, 2, 0, 3)  # [K, 25, B, 5]
    if predictor.maneuvers:
        np.testing.assert_allclose(fut, np.stack(want[0]), rtol=rtol, atol=atol)
        np.testing.assert_allclose(pred.lat_prob, want[1], rtol=rtol, atol=atol)
        np.testing.assert_allclose(pred.lon_prob, want[2], rtol=rtol, atol=atol)
    else:
        np.testing.assert_allclose(fut[0], want, rtol=rtol, atol=atol)
    return want


@VARIANTS
def test_parity_with_numpy_forward(networks, maneuvers):
    predictor, sd = networks[maneuvers]
    hist, nbrs, mask = _reference_batch(np.random.default_rng(1))
    want = _compare_with_numpy(predictor, sd, hist, nbrs, mask, rtol=1e-9, atol=1e-9)
    # The reference layout's own entry point, in the network's float32.
    got = reference_forward(predictor, hist, nbrs, mask)
    np.testing.assert_allclose(got["fut_pred"], np.stack(want[0]) if maneuvers else want, rtol=1e-4, atol=1e-4)
    assert sorted(got) == (["fut_pred", "lat_pred", "lon_pred"] if maneuvers else ["fut_pred"])


@pytest.mark.parametrize("name, count, maneuvers", [("cslstm_no_m.tar", 192_394, False), ("cslstm_m.tar", 194_954, True)])
def test_published_checkpoint_parity(ngsim_checkpoint, name, count, maneuvers):
    path = ngsim_checkpoint(name)
    sd, predictor = read_state_dict(path), load_predictor(path)
    assert sum(v.size for v in sd.values()) == count and all(v.dtype == np.float32 for v in sd.values())
    assert predictor.maneuvers is maneuvers
    hist, nbrs, mask = _reference_batch(np.random.default_rng(2))
    _compare_with_numpy(predictor, sd, hist, nbrs, mask, rtol=1e-9, atol=1e-8)


def _si_batch(seed: int, dtype=np.float64):
    rng = np.random.default_rng(seed)
    hist = rng.normal(size=(B, 16, 2)) * [10.0, 1.0]
    nbr_hist = rng.normal(size=(B, N, 16, 2)) * [20.0, 3.0]
    slot = np.stack([rng.choice([s for s in range(39) if s != 19], N, replace=False) for _ in range(B)])
    weight = rng.uniform(0.2, 1.0, size=(B, N))
    return hist.astype(dtype), nbr_hist.astype(dtype), slot.astype(np.int32), weight.astype(dtype)


def _to_dense(nbr_hist, slot, weight):
    nbrs = np.zeros((B, 39, 16, 2), nbr_hist.dtype)
    occ = np.zeros((B, 39), weight.dtype)
    rows = np.arange(B)[:, None]
    nbrs[rows, slot] = nbr_hist
    occ[rows, slot] = weight
    return nbrs, occ


def _assert_same_prediction(got, want, exact=False):
    for name in ("fut", "mode_prob", "lat_prob", "lon_prob"):
        a, b = getattr(got, name), getattr(want, name)
        if b is None:
            assert a is None, name
        elif exact:
            assert np.array_equal(a, b), name
        else:
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12, err_msg=name)


@VARIANTS
def test_the_dense_grid_is_the_compact_input_with_each_neighbour_in_its_slot(networks, maneuvers):
    predictor = networks[maneuvers][0]
    hist, nbr_hist, slot, weight = _si_batch(3)
    slot[0] = [0, N_SLOTS - 1, 7, 30]  # the grid's first and last slots
    nbrs, occ = _to_dense(nbr_hist, slot, weight)
    model = predictor.model(jnp.float64)
    dense = model(si_to_model(hist), si_to_model(nbrs), occ)
    _assert_same_prediction(dense, _frame(predictor, si_to_model(hist), si_to_model(nbr_hist), slot, weight))
    k = 6 if maneuvers else 1
    assert dense.fut.shape == (B, k, 25, 5) and dense.mode_prob.shape == (B, k)
    np.testing.assert_allclose(dense.mode_prob.sum(-1), 1.0, rtol=1e-12)
    # "weighted" involves all 6 trajectories and the class probabilities of the manoeuvre variant.
    compact = _mean(predictor, hist, nbr_hist, slot, weight, mode="weighted")
    np.testing.assert_allclose(compact, _mean_dense(predictor, hist, nbrs, occ, mode="weighted"), rtol=1e-12, atol=1e-12)


def test_the_mean_is_the_most_probable_mode_or_the_probability_weighted_one(networks):
    predictor = networks[True][0]
    hist, nbr_hist, slot, weight = _si_batch(12)
    pred = _frame(predictor, si_to_model(hist), si_to_model(nbr_hist), slot, weight)
    lat, lon = np.asarray(pred.lat_prob), np.asarray(pred.lon_prob)
    np.testing.assert_allclose(pred.mode_prob, (lon[:, :, None] * lat[:, None, :]).reshape(B, 6), rtol=1e-12)
    fut = np.asarray(pred.fut[..., :2])
    picked = model_to_si(fut[np.arange(B), lon.argmax(-1) * 3 + lat.argmax(-1)])  # mode = lon * 3 + lat
    weighted = model_to_si(np.einsum("bk,bktc->btc", np.asarray(pred.mode_prob), fut))
    # predict_mean decodes only the chosen manoeuvre; the reference decodes 6 and picks one.
    for mode, want in ((None, picked), ("most_probable", picked), ("weighted", weighted)):
        got = _mean(predictor, hist, nbr_hist, slot, weight) if mode is None else _mean(
            predictor, hist, nbr_hist, slot, weight, mode=mode)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(got, model_to_si(select_mean(pred, mode or "most_probable")), rtol=1e-12, atol=1e-12)
    assert not np.allclose(picked, weighted)
    with pytest.raises(ValueError, match="'mean'"):
        predict_mean(predictor, hist, nbr_hist, slot, weight, mode="mean")
    single = networks[False][0]
    one = _frame(single, si_to_model(hist), si_to_model(nbr_hist), slot, weight)
    np.testing.assert_allclose(_mean(single, hist, nbr_hist, slot, weight, mode="weighted"),
                               model_to_si(one.fut[:, 0, :, :2]), rtol=1e-12, atol=1e-12)


def test_padding_shared_slots_and_occupancy_zero(networks):
    predictor = networks[True][0]
    hist, nbr_hist, slot, weight = (si_to_model(a) if i < 2 else a for i, a in enumerate(_si_batch(4)))
    want = _frame(predictor, hist, nbr_hist, slot, weight)
    # A weight-0 neighbour (any history) is the same row marked as padding (slot -1), exactly.
    weight0, padded, other = weight.copy(), slot.copy(), np.array(nbr_hist).copy()
    weight0[:, 1], padded[:, 1], other[:, 1] = 0.0, -1, 1e3
    _assert_same_prediction(_frame(predictor, hist, nbr_hist, slot, weight0),
                            _frame(predictor, hist, other, padded, weight), exact=True)
    # Four more neighbours per row in slots -1, -5, 39 and 40 (outside the grid) change nothing.
    outside = np.tile([[-1, -5, N_SLOTS, N_SLOTS + 1]], (B, 1)).astype(np.int32)
    _assert_same_prediction(_frame(predictor, hist, jnp.concatenate([nbr_hist, 5.0 + nbr_hist], axis=1),
                                   np.concatenate([slot, outside], 1), np.concatenate([weight, np.ones((B, N))], 1)), want)
    # The first neighbour given twice, its weight split 30 / 70, is the one neighbour.
    split_weight = np.concatenate([0.3 * weight[:, :1], weight * np.r_[0.7, 1, 1, 1]], axis=1)
    _assert_same_prediction(_frame(predictor, hist, jnp.concatenate([nbr_hist[:, :1], nbr_hist], axis=1),
                                   np.concatenate([slot[:, :1], slot], 1), split_weight), want)
    # Dense: occupancy 0 in a slot is an empty slot, whatever history it holds.
    nbrs, occ = _to_dense(np.asarray(model_to_si(nbr_hist)), slot, weight0)
    emptied = nbrs.copy()
    emptied[np.arange(B), slot[:, 1]] = 0.0
    assert np.array_equal(_mean_dense(predictor, model_to_si(hist), nbrs, occ),
                          _mean_dense(predictor, model_to_si(hist), emptied, occ))


def test_histories_are_encoded_with_any_leading_axes(networks):
    model = networks[False][0].model(jnp.float64)
    xy = jnp.asarray(np.random.default_rng(5).normal(size=(2, 3, 16, 2)))
    enc = model.encode_tracks(xy)
    assert enc.shape == (2, 3, 64)
    np.testing.assert_allclose(model.encode_tracks(xy.reshape(6, 16, 2)), enc.reshape(6, 64), rtol=1e-12)
    np.testing.assert_allclose(model.encode_tracks(xy[None]), enc[None], rtol=1e-12)


@VARIANTS
def test_float32_in_float32_out(maneuvers):
    predictor = init_predictor(maneuvers=maneuvers, seed=2)
    hist, nbr_hist, slot, weight = _si_batch(10, np.float32)
    nbrs, occ = _to_dense(nbr_hist, slot, weight)
    pred = _frame(predictor, hist, nbr_hist, slot, weight)
    dense = predictor.model()(hist, nbrs, occ)
    for p in (pred, dense):
        fields = [p.fut, p.mode_prob] + ([p.lat_prob, p.lon_prob] if maneuvers else [])
        assert {f.dtype for f in fields} == {jnp.dtype(jnp.float32)}
    # float64 occupancy: the mean keeps the histories' float32
    outs = (_mean(predictor, hist, nbr_hist, slot, weight), _mean_dense(predictor, hist, nbrs, occ.astype(np.float64)))
    for out in outs:
        assert out.dtype == jnp.float32 and out.shape == (B, 25, 2) and np.all(np.isfinite(out))


@jax.jit
def _loss_compact(predictor, probe, hist, nbr_hist, weight, slot):
    return jnp.sum(probe * predict_mean(predictor, hist, nbr_hist, slot, weight, mode="weighted"))


@jax.jit
def _loss_dense(predictor, probe, occ, hist, nbrs):
    return jnp.sum(probe * predict_mean_dense(predictor, hist, nbrs, occ, mode="weighted"))


_grads = {_loss_compact: jax.jit(jax.grad(_loss_compact, argnums=(2, 3, 4))), _loss_dense: jax.jit(jax.grad(_loss_dense, argnums=2))}


@VARIANTS
def test_gradients_match_finite_differences(networks, maneuvers):
    predictor = networks[maneuvers][0]
    hist, nbr_hist, slot, weight = _si_batch(5)
    nbrs, occ = _to_dense(nbr_hist, slot, weight)
    probe = np.random.default_rng(6).normal(size=(B, 25, 2))
    rng = np.random.default_rng(7)
    eps = 1e-6
    for fn, args, fixed in ((_loss_compact, (hist, nbr_hist, weight), (slot,)), (_loss_dense, (occ,), (hist, nbrs))):
        grads = _grads[fn](predictor, probe, *args, *fixed)
        grads = grads if isinstance(grads, tuple) else (grads,)
        for i, (arg, g) in enumerate(zip(args, grads, strict=True)):
            # Only occupied slots: at an empty slot of the dense grid the max-pool compares
            # identical empty regions (a tie), where the network has no derivative.
            v = rng.normal(size=arg.shape) * (occ > 0 if fn is _loss_dense else 1.0)
            plus = [a + eps * v if j == i else a for j, a in enumerate(args)]
            minus = [a - eps * v if j == i else a for j, a in enumerate(args)]
            fd = (fn(predictor, probe, *plus, *fixed) - fn(predictor, probe, *minus, *fixed)) / (2 * eps)
            np.testing.assert_allclose(np.sum(g * v), fd, rtol=1e-6, atol=1e-8)


def test_values_and_gradients_finite_at_extremes(networks):
    predictor = networks[True][0]
    hist, nbr_hist, slot, weight = _si_batch(8)
    probe = np.ones((B, 25, 2))
    for scale, w in ((1e4, 0.0), (1e4, 1.0), (0.0, 0.0), (0.0, 1.0)):
        args = (hist * scale, nbr_hist * scale, np.full_like(weight, w))
        out = _loss_compact(predictor, probe, *args, slot)
        grads = _grads[_loss_compact](predictor, probe, *args, slot)
        assert np.isfinite(out) and all(np.all(np.isfinite(g)) for g in grads)
