"""The predictor's public face: the SI / model frame boundary by hand, the mean a prediction gives
in each mode, a predictor called through the `Predictor` protocol, the untrained predictor (its
variant, seed and PyTorch's initialisation), and what each source `load_predictor` reads
carries as its validation RMSE."""

from __future__ import annotations

import json

import _torch_zip
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from diffsense.predictors import (
    CSLSTM_SPEC,
    DEFAULT_WEIGHTS,
    Prediction,
    Predictor,
    PredictorInputs,
    init_predictor,
    load_predictor,
    model_to_si,
    predict_mean,
    read_card,
    save_weights,
    select_mean,
    si_to_model,
    state_dict_from_model,
)

RNG = np.random.default_rng(11)


def test_the_frame_boundary_is_feet_with_lateral_to_the_right():
    # 30.48 m ahead and 3.048 m to the left is (lateral 10 ft to the LEFT = -10, 100 ft forward).
    xy = jnp.array([[30.48, 3.048], [-6.096, -1.524]])
    np.testing.assert_allclose(si_to_model(xy), [[-10.0, 100.0], [5.0, -20.0]], rtol=1e-15)
    np.testing.assert_allclose(model_to_si(jnp.array([[-10.0, 100.0], [5.0, -20.0]])), xy, rtol=1e-15)
    np.testing.assert_allclose(si_to_model(np.array([1.0, 1.0])), [-1 / 0.3048, 1 / 0.3048])
    batch = jax.random.normal(jax.random.key(0), (3, 4, 16, 2), jnp.float64) * 50.0
    assert si_to_model(batch).shape == (3, 4, 16, 2)
    np.testing.assert_allclose(model_to_si(si_to_model(batch)), batch, rtol=1e-14)


def test_the_mean_is_the_one_mode_the_most_probable_mode_or_the_weighted_one():
    one = RNG.normal(size=(2, 1, 25, 5))
    got = select_mean(Prediction(fut=jnp.asarray(one), mode_prob=jnp.ones((2, 1))), "weighted")
    np.testing.assert_array_equal(np.asarray(got), one[:, 0, :, :2])
    fut = RNG.normal(size=(2, 6, 25, 5))
    lon = np.array([[0.3, 0.7], [0.9, 0.1]])  # (normal, braking): row 0 brakes, row 1 does not
    lat = np.array([[0.2, 0.5, 0.3], [0.1, 0.2, 0.7]])  # (keep, left, right): row 0 left, row 1 right
    mode_prob = RNG.dirichlet(np.ones(6), size=2)
    pred = Prediction(fut=jnp.asarray(fut), mode_prob=jnp.asarray(mode_prob), lat_prob=jnp.asarray(lat),
                      lon_prob=jnp.asarray(lon))
    most = np.asarray(select_mean(pred))
    np.testing.assert_array_equal(most[0], fut[0, 1 * 3 + 1, :, :2])  # mode = lon * 3 + lat
    np.testing.assert_array_equal(most[1], fut[1, 0 * 3 + 2, :, :2])
    want = sum(mode_prob[:, k, None, None] * fut[:, k, :, :2] for k in range(6))
    np.testing.assert_allclose(np.asarray(select_mean(pred, "weighted")), want, rtol=1e-13)
    with pytest.raises(ValueError, match="'mean'"):
        select_mean(pred, "mean")


def test_a_predictor_called_is_predict_mean_of_its_inputs():
    predictor = init_predictor()
    assert isinstance(predictor, Predictor) and predictor.spec is CSLSTM_SPEC
    hist = jnp.asarray(RNG.normal(size=(3, 16, 2)))
    nbr_hist = jnp.asarray(RNG.normal(size=(3, 2, 16, 2)) * 5.0)
    slot = jnp.asarray([[1, 20], [7, 0], [38, 13]])
    weight = jnp.asarray([[1.0, 0.5], [0.25, 0.0], [1.0, 1.0]])
    called = predictor(PredictorInputs(hist=hist, nbr_hist=nbr_hist, nbr_slot=slot, nbr_weight=weight))
    np.testing.assert_array_equal(np.asarray(called), np.asarray(predict_mean(predictor, hist, nbr_hist, slot, weight)))
    other = predict_mean(predictor, hist, nbr_hist, slot, weight * 0.5)  # the inputs matter
    assert not np.array_equal(np.asarray(called), np.asarray(other))


def test_the_untrained_predictor_is_single_mode_from_seed_0_unless_asked():
    default, zero, one = (state_dict_from_model(p.model()) for p in (init_predictor(), init_predictor(False, 0),
                                                                     init_predictor(False, 1)))
    assert init_predictor().maneuvers is False and init_predictor(maneuvers=True).maneuvers is True
    assert all(np.array_equal(default[k], zero[k]) for k in default)
    assert all(not np.array_equal(default[k], one[k]) for k in default)  # every parameter, biases too
    assert default["dec_lstm.weight_ih_l0"].shape == (512, 112)  # social 80 + dynamics 32
    manoeuvre = state_dict_from_model(init_predictor(maneuvers=True).model())
    assert manoeuvre["dec_lstm.weight_ih_l0"].shape == (512, 117)  # + 3 lateral + 2 longitudinal
    assert sorted(manoeuvre) == sorted(default)


def _fan_in(key: str, sd: dict) -> int:
    """PyTorch's: a Linear's inputs, a convolution's inputs x kernel, an LSTM's hidden size."""
    layer = key.rsplit(".", 1)[0]
    if layer.endswith("lstm"):
        return sd[f"{layer}.weight_hh_l0"].shape[1]
    weight = sd[f"{layer}.weight"]
    return int(np.prod(weight.shape[1:]))


def test_initialisation_is_pytorchs_uniform_in_one_over_root_fan_in():
    sd = state_dict_from_model(init_predictor(seed=3).model())
    assert _fan_in("enc_lstm.bias_ih_l0", sd) == 64 and _fan_in("soc_conv.bias", sd) == 64 * 3 * 3
    assert _fan_in("ip_emb.weight", sd) == 2 and _fan_in("op.bias", sd) == 128
    for key, w in sd.items():
        bound = 1.0 / np.sqrt(_fan_in(key, sd))
        assert w.dtype == np.float32 and np.abs(w).max() <= bound, key
        if w.size >= 400:  # a uniform fills its interval: the extremes and the variance bound^2 / 3
            assert w.min() < -0.98 * bound and w.max() > 0.98 * bound, key
            assert abs(w.var() / (bound**2 / 3) - 1.0) < 0.15, key
    assert not np.array_equal(sd["dec_lstm.bias_ih_l0"], sd["dec_lstm.bias_hh_l0"])  # two biases, two draws


def test_the_default_predictor_is_the_shipped_weight_file_with_its_cards_rmse():
    default, named = load_predictor(), load_predictor(DEFAULT_WEIGHTS)
    a, b = (state_dict_from_model(p.model()) for p in (default, named))
    assert sorted(a) == sorted(b) and all(np.array_equal(a[k], b[k]) for k in a)
    card = tuple(float(v) for v in read_card(DEFAULT_WEIGHTS)["validation"]["rmse_m"]["cslstm"])
    assert default.validation_rmse_m == card == named.validation_rmse_m and len(card) == 5


def test_each_source_carries_its_validation_rmse(tmp_path):
    model = init_predictor(seed=4).model()
    path = tmp_path / "w.msgpack"
    save_weights(path, model)
    assert not (tmp_path / "w.json").exists()  # no card asked for, none written
    assert load_predictor(path).validation_rmse_m is None
    (tmp_path / "w.json").write_text(json.dumps({"validation": {"rmse_m": {"cslstm": [1, 2.5]}}}))
    assert load_predictor(path).validation_rmse_m == (1.0, 2.5)
    (tmp_path / "w.json").write_text(json.dumps({"validation": {}}))
    assert load_predictor(path).validation_rmse_m is None
    # A PyTorch checkpoint carries the published NGSIM test RMSE (Deo & Trivedi 2018).
    _torch_zip.write(tmp_path / "c.tar", state_dict_from_model(model))
    assert load_predictor(tmp_path / "c.tar").validation_rmse_m == (0.61, 1.27, 2.09, 3.10, 4.37)
