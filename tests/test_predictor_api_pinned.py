"""The predictor's public functions pinned by hand: the mean a prediction gives in each mode, a
predictor called through the `Predictor` protocol, the untrained predictor's default seed, and a
refused checkpoint named in its message."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

import _torch_zip
from diffsense.runtime._errors import InputError
from diffsense.predictors import (
    PredictorInputs,
    init_predictor,
    load_predictor,
    predict_mean,
    select_mean,
    state_dict_from_model,
)
from diffsense.predictors._model import Prediction

RNG = np.random.default_rng(11)


def test_the_single_mode_mean_is_its_one_mode():
    fut = RNG.normal(size=(2, 1, 25, 5))
    got = select_mean(Prediction(fut=jnp.asarray(fut), mode_prob=jnp.ones((2, 1))))
    np.testing.assert_array_equal(np.asarray(got), fut[:, 0, :, :2])


def test_the_manoeuvre_mean_is_the_most_probable_mode_or_the_weighted_one():
    fut = RNG.normal(size=(2, 6, 25, 5))
    lon = np.array([[0.3, 0.7], [0.9, 0.1]])  # (normal, braking): row 0 brakes, row 1 does not
    lat = np.array([[0.2, 0.5, 0.3], [0.1, 0.2, 0.7]])  # (keep, left, right): row 0 left, row 1 right
    mode_prob = RNG.dirichlet(np.ones(6), size=2)
    pred = Prediction(fut=jnp.asarray(fut), mode_prob=jnp.asarray(mode_prob), lat_prob=jnp.asarray(lat),
                      lon_prob=jnp.asarray(lon))
    most = np.asarray(select_mean(pred))
    np.testing.assert_array_equal(most[0], fut[0, 1 * 3 + 1, :, :2])  # mode = lon * 3 + lat
    np.testing.assert_array_equal(most[1], fut[1, 0 * 3 + 2, :, :2])
    weighted = np.asarray(select_mean(pred, "weighted"))
    want = sum(mode_prob[:, k, None, None] * fut[:, k, :, :2] for k in range(6))
    np.testing.assert_allclose(weighted, want, rtol=1e-13)
    with pytest.raises(ValueError, match="mode must be 'most_probable' or 'weighted', got 'mean'"):
        select_mean(pred, "mean")


def test_a_predictor_called_is_predict_mean_of_its_inputs():
    predictor = init_predictor()
    hist = jnp.asarray(RNG.normal(size=(3, 16, 2)))
    nbr_hist = jnp.asarray(RNG.normal(size=(3, 2, 16, 2)) * 5.0)
    slot = jnp.asarray([[1, 20], [7, 0], [38, 13]])
    weight = jnp.asarray([[1.0, 0.5], [0.25, 0.0], [1.0, 1.0]])
    called = predictor(PredictorInputs(hist=hist, nbr_hist=nbr_hist, nbr_slot=slot, nbr_weight=weight))
    np.testing.assert_array_equal(np.asarray(called), np.asarray(predict_mean(predictor, hist, nbr_hist, slot, weight)))
    other = predict_mean(predictor, hist, nbr_hist, slot, weight * 0.5)  # the inputs matter
    assert not np.array_equal(np.asarray(called), np.asarray(other))


def test_the_untrained_predictor_defaults_to_seed_0_single_mode():
    default, zero, one = init_predictor(), init_predictor(False, 0), init_predictor(False, 1)
    assert default.maneuvers is False
    a, b, c = (state_dict_from_model(p.model()) for p in (default, zero, one))
    assert all(np.array_equal(a[k], b[k]) for k in a) and not np.array_equal(a["op.weight"], c["op.weight"])


def test_a_refused_checkpoint_is_named_in_the_message(tmp_path):
    sd = state_dict_from_model(init_predictor().model())
    path = tmp_path / "c.tar"
    _torch_zip.write(path, sd | {"op.bias": np.zeros(4, np.float32)})
    with pytest.raises(InputError) as info:
        load_predictor(path)
    assert str(info.value) == f"{path}: op.bias has shape (4,), expected (5,)"


def test_an_untrained_manoeuvre_predictor_has_six_modes():
    predictor = init_predictor(maneuvers=True)
    assert predictor.maneuvers is True and "op_lat.weight" in state_dict_from_model(predictor.model())


def test_the_default_predictor_is_the_shipped_weight_file_with_its_cards_rmse():
    from diffsense.predictors._weights import DEFAULT_WEIGHTS, read_card

    default, named = load_predictor(), load_predictor(DEFAULT_WEIGHTS)
    a, b = (state_dict_from_model(p.model()) for p in (default, named))
    assert sorted(a) == sorted(b) and all(np.array_equal(a[k], b[k]) for k in a)
    card = tuple(float(v) for v in read_card(DEFAULT_WEIGHTS)["validation"]["rmse_m"]["cslstm"])
    assert default.validation_rmse_m == card == named.validation_rmse_m and len(card) == 5


def test_the_mean_defaults_to_the_most_probable_manoeuvre_and_keeps_float32():
    from diffsense.predictors import predict_mean_dense

    predictor = init_predictor(maneuvers=True, seed=2)
    hist = jnp.asarray(RNG.normal(size=(3, 16, 2)), jnp.float32)
    nbr_hist = jnp.asarray(RNG.normal(size=(3, 2, 16, 2)) * 5.0, jnp.float32)
    slot, weight = jnp.asarray([[1, 20], [7, 0], [38, 13]]), jnp.ones((3, 2), jnp.float32)
    got = predict_mean(predictor, hist, nbr_hist, slot, weight)
    np.testing.assert_array_equal(np.asarray(got), np.asarray(predict_mean(predictor, hist, nbr_hist, slot, weight,
                                                                           "most_probable")))
    nbrs = jnp.asarray(RNG.normal(size=(3, 39, 16, 2)) * 5.0, jnp.float32)
    occupancy = jnp.asarray(RNG.uniform(size=(3, 39)))  # float64: the mean keeps the histories' float32
    dense = predict_mean_dense(predictor, hist, nbrs, occupancy)
    assert got.dtype == dense.dtype == jnp.float32
    np.testing.assert_array_equal(np.asarray(dense), np.asarray(predict_mean_dense(predictor, hist, nbrs, occupancy,
                                                                                   "most_probable")))
