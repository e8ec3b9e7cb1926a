"""CS-LSTM: parity with an independent numpy forward, dense == compact, occupancy 0 == absent,
gradients against finite differences, the SI boundary, and everything under jit."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import _numpy_cslstm
from _textbook_lstm import textbook_lstm
from diffsense.predictors._model import model_from_params, param_shapes
from diffsense.predictors import (
    CSLSTMPredictor,
    init_predictor,
    load_predictor,
    model_to_si,
    output_activation,
    predict_mean,
    predict_mean_dense,
    predict_model_frame,
    read_state_dict,
    reference_to_compact,
    select_mean,
    si_to_model,
    state_dict_from_model,
)

B, N = 3, 4
VARIANTS = [False, True]


def _random_predictor(maneuvers: bool, seed: int = 0) -> CSLSTMPredictor:
    # PyTorch's init is small; widen it so that every layer matters in the comparison.
    rng = np.random.default_rng(seed)
    params = jax.tree.map(
        lambda shape: (rng.uniform(-0.5, 0.5, size=shape)).astype(np.float32),
        param_shapes(maneuvers),
        is_leaf=lambda x: isinstance(x, tuple),
    )
    return CSLSTMPredictor.from_model(model_from_params(maneuvers, params))


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


@pytest.fixture(scope="module")
def predictors():
    return {m: _random_predictor(m) for m in VARIANTS}


@pytest.fixture(scope="module")
def forward64():
    return _forward


# One jitted function per entry point; the predictor is always an argument (a closed-over
# predictor would become an XLA constant and be constant-folded at great compile cost).
_forward = jax.jit(predict_model_frame)
_mean = jax.jit(predict_mean, static_argnames="mode")
_mean_dense = jax.jit(predict_mean_dense, static_argnames="mode")


def _compare_with_numpy(predictor, sd, forward, hist, nbrs, mask, rtol, atol):
    inputs = [np.asarray(a, np.float64) if a.dtype.kind == "f" else a for a in reference_to_compact(hist, nbrs, mask)]
    pred = forward(predictor, *inputs)
    want = _numpy_cslstm.forward(sd, hist, nbrs, mask)
    fut = np.asarray(pred.fut).transpose(1, 2, 0, 3)  # [K, 25, B, 5]
    if predictor.maneuvers:
        np.testing.assert_allclose(fut, np.stack(want[0]), rtol=rtol, atol=atol)
        np.testing.assert_allclose(pred.lat_prob, want[1], rtol=rtol, atol=atol)
        np.testing.assert_allclose(pred.lon_prob, want[2], rtol=rtol, atol=atol)
    else:
        np.testing.assert_allclose(fut[0], want, rtol=rtol, atol=atol)


@pytest.mark.parametrize("maneuvers", VARIANTS, ids=["single", "maneuver"])
def test_parity_with_numpy_forward(predictors, forward64, maneuvers):
    predictor = predictors[maneuvers]
    sd = state_dict_from_model(predictor.model())
    hist, nbrs, mask = _reference_batch(np.random.default_rng(1))
    _compare_with_numpy(predictor, sd, forward64, hist, nbrs, mask, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("name, maneuvers", [("cslstm_no_m.tar", False), ("cslstm_m.tar", True)])
def test_published_checkpoint_parity(ngsim_checkpoint, forward64, name, maneuvers):
    path = ngsim_checkpoint(name)
    predictor = load_predictor(path)
    assert predictor.maneuvers is maneuvers
    hist, nbrs, mask = _reference_batch(np.random.default_rng(2))
    _compare_with_numpy(predictor, read_state_dict(path), forward64, hist, nbrs, mask, rtol=1e-9, atol=1e-8)


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


@pytest.mark.parametrize("maneuvers", VARIANTS, ids=["single", "maneuver"])
def test_dense_equals_compact(predictors, maneuvers):
    hist, nbr_hist, slot, weight = _si_batch(3)
    nbrs, occ = _to_dense(nbr_hist, slot, weight)
    # "weighted" involves all 6 trajectories and the class probabilities of the manoeuvre variant.
    compact = _mean(predictors[maneuvers], hist, nbr_hist, slot, weight, mode="weighted")
    dense = _mean_dense(predictors[maneuvers], hist, nbrs, occ, mode="weighted")
    np.testing.assert_allclose(compact, dense, rtol=1e-12, atol=1e-12)


def test_most_probable_mean_is_the_reference_pick_of_all_six(predictors):
    # predict_mean decodes only the chosen manoeuvre; the reference decodes 6 and picks one.
    hist, nbr_hist, slot, weight = _si_batch(12)
    pred = _forward(predictors[True], si_to_model(hist), si_to_model(nbr_hist), slot, weight)
    picked = model_to_si(select_mean(pred, "most_probable"))
    mean = _mean(predictors[True], hist, nbr_hist, slot, weight, mode="most_probable")
    np.testing.assert_allclose(mean, picked, rtol=1e-12, atol=1e-12)
    assert not np.allclose(mean, model_to_si(select_mean(pred, "weighted")))


def test_occupancy_zero_is_an_absent_neighbour_exactly(predictors):
    predictor = predictors[True]
    hist, nbr_hist, slot, weight = _si_batch(4)
    fwd = _forward
    # Compact: a weight-0 neighbour (any history) == the same row marked as padding (slot -1).
    weight0 = weight.copy()
    weight0[:, 1] = 0.0
    padded_slot = slot.copy()
    padded_slot[:, 1] = -1
    other = nbr_hist.copy()
    other[:, 1] = 1e3
    a = fwd(predictor, hist, nbr_hist, slot, weight0)
    b = fwd(predictor, hist, other, padded_slot, weight)
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
        assert np.array_equal(x, y)
    # Dense: occupancy 0 in a slot == an empty slot, whatever history it holds.
    nbrs, occ = _to_dense(nbr_hist, slot, weight0)
    nbrs_empty = nbrs.copy()
    nbrs_empty[np.arange(B), slot[:, 1]] = 0.0
    dense = _mean_dense
    assert np.array_equal(dense(predictor, hist, nbrs, occ), dense(predictor, hist, nbrs_empty, occ))


@jax.jit
def _loss_compact(predictor, probe, hist, nbr_hist, weight, slot):
    return jnp.sum(probe * predict_mean(predictor, hist, nbr_hist, slot, weight, mode="weighted"))


@jax.jit
def _loss_dense(predictor, probe, occ, hist, nbrs):
    return jnp.sum(probe * predict_mean_dense(predictor, hist, nbrs, occ, mode="weighted"))


_GRADS = {}


def _grad(fn, n_args):
    """jit(grad) w.r.t. the n_args arguments after (predictor, probe), built once per function."""
    if fn not in _GRADS:
        _GRADS[fn] = jax.jit(jax.grad(fn, argnums=tuple(range(2, 2 + n_args))))
    return _GRADS[fn]


@pytest.mark.parametrize("maneuvers", VARIANTS, ids=["single", "maneuver"])
def test_gradients_match_finite_differences(predictors, maneuvers):
    predictor = predictors[maneuvers]
    hist, nbr_hist, slot, weight = _si_batch(5)
    nbrs, occ = _to_dense(nbr_hist, slot, weight)
    probe = np.random.default_rng(6).normal(size=(B, 25, 2))

    rng = np.random.default_rng(7)
    eps = 1e-6
    cases = ((_loss_compact, (hist, nbr_hist, weight), (slot,)), (_loss_dense, (occ,), (hist, nbrs)))
    for fn, args, fixed in cases:
        grads = _grad(fn, len(args))(predictor, probe, *args, *fixed)
        for i, (arg, g) in enumerate(zip(args, grads)):
            # Only occupied slots: at an empty slot of the dense grid the reference's max-pool
            # compares identical empty regions (a tie), where the network has no derivative.
            v = rng.normal(size=arg.shape) * (occ > 0 if fn is _loss_dense else 1.0)
            plus = [a + eps * v if j == i else a for j, a in enumerate(args)]
            minus = [a - eps * v if j == i else a for j, a in enumerate(args)]
            fd = (fn(predictor, probe, *plus, *fixed) - fn(predictor, probe, *minus, *fixed)) / (2 * eps)
            np.testing.assert_allclose(np.sum(g * v), fd, rtol=1e-6, atol=1e-8)


def test_values_and_gradients_finite_at_extremes(predictors):
    predictor = predictors[True]
    hist, nbr_hist, slot, weight = _si_batch(8)
    probe = np.ones((B, 25, 2))
    grad = _grad(_loss_compact, 3)
    for scale, w in ((1e4, 0.0), (1e4, 1.0), (0.0, 0.0), (0.0, 1.0)):
        args = (hist * scale, nbr_hist * scale, np.full_like(weight, w))
        out = _loss_compact(predictor, probe, *args, slot)
        grads = grad(predictor, probe, *args, slot)
        assert np.isfinite(out) and all(np.all(np.isfinite(g)) for g in grads)


def test_frame_round_trip_and_axes():
    xy_m = np.random.default_rng(9).normal(size=(5, 16, 2)) * 30
    np.testing.assert_allclose(model_to_si(si_to_model(xy_m)), xy_m, rtol=1e-15, atol=1e-12)
    # 1 m forward and 1 m to the left is 3.28 ft forward and 3.28 ft to the left (lateral < 0).
    np.testing.assert_allclose(si_to_model(np.array([1.0, 1.0])), [-1 / 0.3048, 1 / 0.3048])
    np.testing.assert_allclose(model_to_si(np.array([15.0, -30.0])), [-30 * 0.3048, -15 * 0.3048])


def test_float32_in_float32_out():
    hist, nbr_hist, slot, weight = _si_batch(10, np.float32)
    predictor = init_predictor(maneuvers=False, seed=2)
    assert jax.tree.leaves(predictor.state)[0].dtype == jnp.float32
    out = _mean(predictor, hist, nbr_hist, slot, weight)
    assert out.dtype == jnp.float32 and out.shape == (B, 25, 2) and np.all(np.isfinite(out))


def test_small_public_functions_under_jit_equal_eager():
    # predict_mean, predict_mean_dense and predict_model_frame run under jit in every test above.
    hist, nbr_hist, _, _ = _si_batch(11)
    cases = [
        (si_to_model, (hist,)),
        (model_to_si, (hist,)),
        (output_activation, (nbr_hist[..., :5, :].reshape(B, -1, 5),)),
    ]
    for fn, args in cases:
        np.testing.assert_allclose(jax.jit(fn)(*args), fn(*args), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("remat_bytes", [16 * 2**20, 0], ids=["gates-kept", "gates-recomputed"])
def test_lstm_hand_written_backward_matches_autodiff(monkeypatch, remat_bytes):
    # Both recurrences, value and gradient w.r.t. every argument (weights too: training uses them),
    # against JAX's autodiff of the textbook LSTM, in float64. Both ways of the backward pass:
    # with the forward pass's gates kept, and recomputed (what reverse mode runs for batches above
    # REMAT_BYTES, such as the main job's scenes in a problem of several parameters, and no small
    # test reaches unless the threshold is lowered).
    from diffsense.predictors import _lstm
    from diffsense.predictors._lstm import lstm_last, lstm_repeat

    monkeypatch.setattr(_lstm, "REMAT_BYTES", remat_bytes)
    rng = np.random.default_rng(13)
    t, n, n_in, hidden = 5, 3, 6, 4
    w = [rng.normal(size=s) for s in ((n_in, 4 * hidden), (hidden, 4 * hidden), (4 * hidden,))]
    xs, x1 = rng.normal(size=(t, n, n_in)), rng.normal(size=(n, n_in))
    probe_last, probe_all = rng.normal(size=(n, hidden)), rng.normal(size=(t, n, hidden))
    emb = [rng.normal(size=(2, n_in)), rng.normal(size=n_in)]
    xy = rng.normal(size=(t, n, 2))
    # Pre-activations of the embedding exactly at leaky_relu's kink: a zero history row and a zero
    # bias give pre = 0, where the primal takes the slope-1 branch and so must the gradient.
    xy[:, 0] = 0.0
    emb[1][:2] = 0.0

    def embedded(x, a, c):  # leaky_relu(x @ a + c), slope 0.1
        z = x @ a + c
        return jnp.where(z >= 0, z, 0.1 * z)

    cases = [
        (lambda x, *p: lstm_last(x, *p), lambda x, *p: textbook_lstm(x, *p)[-1], xs, probe_last),
        (
            lambda x, *p: lstm_last(x, *p[:3], emb=p[3:]),
            lambda x, *p: textbook_lstm(embedded(x, *p[3:]), *p[:3])[-1],
            xy,
            probe_last,
        ),
        (
            lambda x, *p: lstm_repeat(t, x, *p),
            lambda x, *p: textbook_lstm(jnp.broadcast_to(x, (t,) + x.shape), *p),
            x1,
            probe_all,
        ),
    ]
    for case, (got_fn, want_fn, x, probe) in enumerate(cases):
        p = w + emb if case == 1 else w
        np.testing.assert_allclose(got_fn(x, *p), want_fn(x, *p), rtol=1e-13, atol=1e-14)
        argnums = tuple(range(len(p) + 1))
        got = jax.grad(lambda *a: jnp.sum(probe * got_fn(*a)), argnums=argnums)(x, *p)
        want = jax.grad(lambda *a: jnp.sum(probe * want_fn(*a)), argnums=argnums)(x, *p)
        for g, ref in zip(got, want, strict=True):
            np.testing.assert_allclose(g, ref, rtol=1e-12, atol=1e-13)
        # Under jit as well (XLA fuses the unrolled forward differently from eager mode).
        np.testing.assert_allclose(jax.jit(got_fn)(x, *p), want_fn(x, *p), rtol=1e-13, atol=1e-14)


def test_gates_are_kept_up_to_remat_bytes_and_recomputed_above():
    # The reverse pass keeps the forward pass's gates [T, N, 4H] while they take at most
    # REMAT_BYTES, and recomputes them in the backward pass above: the boundary in rows.
    from functools import partial

    from diffsense.predictors import _lstm

    t, n_in, hidden = 16, 32, 64
    row_bytes = t * 4 * hidden * np.dtype(np.float32).itemsize
    fit = _lstm.REMAT_BYTES // row_bytes
    assert fit * row_bytes == _lstm.REMAT_BYTES  # the boundary falls on a whole row here
    weights = [jax.ShapeDtypeStruct(s, jnp.float32) for s in ((n_in, 4 * hidden), (hidden, 4 * hidden), (4 * hidden,))]
    for rows, kept in ((fit, True), (fit + 1, False)):
        x = jax.ShapeDtypeStruct((t, rows, n_in), jnp.float32)
        _, residuals = jax.eval_shape(partial(_lstm._fwd, t, True), x, None, *weights)
        assert (residuals[4] is not None) == kept, rows


@pytest.mark.parametrize("remat_bytes", [16 * 2**20, 0], ids=["gates-kept", "gates-recomputed"])
def test_float32_recurrences_stay_float32_in_every_mode(monkeypatch, remat_bytes):
    # The predictor runs in float32 inside a float64 solver (x64 on): the recurrences' values,
    # their reverse-mode gradients and their forward-mode tangents keep float32 throughout (a
    # float64 state or zero would promote the whole pass, at twice the cost).
    from diffsense.predictors import _lstm, forward_mode
    from diffsense.predictors._lstm import lstm_last, lstm_repeat

    monkeypatch.setattr(_lstm, "REMAT_BYTES", remat_bytes)
    rng = np.random.default_rng(3)
    t, n, n_in, hidden = 4, 3, 5, 4
    f32 = lambda *shape: jnp.asarray(rng.normal(size=shape), jnp.float32)  # noqa: E731
    w = (f32(n_in, 4 * hidden), f32(hidden, 4 * hidden), f32(4 * hidden))
    emb = (f32(2, n_in), f32(n_in))
    cases = [
        (lambda x: lstm_last(x, *w), f32(t, n, n_in)),
        (lambda x: lstm_last(x, *w, emb=emb), f32(t, n, 2)),
        (lambda x: lstm_repeat(t, x, *w), f32(n, n_in)),
    ]
    for fn, x in cases:
        value, pullback = jax.vjp(fn, x)
        (grad,) = pullback(jnp.ones_like(value))
        with forward_mode():
            primal, tangent = jax.jvp(fn, (x,), (jnp.ones_like(x),))
        dtypes = {a.dtype for a in (value, grad, primal, tangent)}
        assert dtypes == {jnp.dtype(jnp.float32)}, dtypes


def test_leaky_relu_takes_the_slope_one_branch_at_zero():
    # One convention at the kink for every way the network is differentiated: the hand-written
    # reverse and forward rules take slope 1 at a pre-activation of exactly 0, and so does
    # autodiff of the primal (the other layers, and the reference's checks).
    from diffsense.predictors._lstm_cell import leaky_relu

    x = jnp.array([-2.0, 0.0, 3.0])
    np.testing.assert_array_equal(leaky_relu(x), [-0.2, 0.0, 3.0])
    np.testing.assert_array_equal(jax.vmap(jax.grad(leaky_relu))(x), [0.1, 1.0, 1.0])
