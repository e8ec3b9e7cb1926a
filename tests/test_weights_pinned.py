"""The predictor's weight files and layout conversion pinned by hand: every check of the project's
msgpack format and of a PyTorch `state_dict` refuses with its own one-line message, and the
layouts (PyTorch [out, in] / [4H, in] / OIHW against ours [in, out] / [in, 4H] / HWIO) are the
transposes written out element by element."""

from __future__ import annotations

import json

import numpy as np
import pytest
from flax import serialization

from diffsense.runtime._errors import InputError
from diffsense.predictors import _api, load_predictor, read_card, state_dict_from_model
from diffsense.predictors._convert import model_from_state_dict
from diffsense.predictors._model import model_from_params, param_shapes
from diffsense.predictors._weights import (
    FORMAT,
    VERSION,
    load_weights,
    model_from_bytes,
    save_weights,
)


def _params(maneuvers: bool) -> dict:
    rng = np.random.default_rng(3 + int(maneuvers))
    return {k: {kk: rng.uniform(-0.3, 0.3, size=vv).astype(np.float32) for kk, vv in v.items()}
            for k, v in param_shapes(maneuvers).items()}


@pytest.fixture(scope="module")
def params():
    return _params(False)


def _file(groups: dict, **changes) -> bytes:
    tree = {"format": FORMAT, "version": VERSION, "maneuvers": False, "params": groups} | changes
    return serialization.msgpack_serialize(tree)


def _refused(data: bytes, reason: str) -> None:
    with pytest.raises(InputError) as info:
        model_from_bytes(data, "w.msgpack")
    assert str(info.value) == f"w.msgpack: {reason}"


def test_a_weight_file_loads_as_written(params):
    model = model_from_bytes(_file(params), "w.msgpack")
    assert model.maneuvers is False
    for name, group in params.items():
        for key, value in group.items():
            np.testing.assert_array_equal(np.asarray(getattr(getattr(model, name), key)), value)
    float64 = {k: {kk: vv.astype(np.float64) for kk, vv in v.items()} for k, v in params.items()}
    assert np.asarray(model_from_bytes(_file(float64), "w.msgpack").op.bias).dtype == np.float32


def test_the_format_and_version_must_be_the_project_s(params):
    wrong = f"not a {FORMAT} v{VERSION} weight file"
    _refused(_file(params, format="other"), wrong)
    _refused(_file(params, version=VERSION + 1), wrong)
    _refused(serialization.msgpack_serialize([1, 2]), wrong)
    with pytest.raises(InputError, match=r"^w\.msgpack: not a msgpack weight file \("):
        model_from_bytes(b"\xc1", "w.msgpack")


def test_every_group_and_array_must_match_the_network(params):
    _refused(_file(params, params=[1]), "parameter groups do not match the CS-LSTM")
    _refused(_file({k: v for k, v in params.items() if k != "op"}), "parameter groups do not match the CS-LSTM")
    _refused(_file(params | {"extra": {"w": np.zeros(2, np.float32)}}), "parameter groups do not match the CS-LSTM")
    _refused(_file(params | {"op": [1]}), "parameters of op do not match the CS-LSTM")
    _refused(_file(params | {"op": {"weight": params["op"]["weight"]}}), "parameters of op do not match the CS-LSTM")
    shape = param_shapes(False)["op"]["bias"]
    bad = f"op.bias is not a finite float array of shape {shape}"
    for value in (np.zeros((6,), np.float32), params["op"]["bias"].astype(np.int32),
                  np.full(shape, np.nan, np.float32), np.full(shape, np.inf, np.float32)):
        _refused(_file(params | {"op": params["op"] | {"bias": value}}), bad)


def test_the_variant_comes_from_the_file():
    maneuver = _params(True)
    model = model_from_bytes(_file(maneuver, maneuvers=True), "w.msgpack")
    assert model.maneuvers is True
    shape = param_shapes(False)["dec_lstm"]["w_ih"]  # read as single-mode: 5 inputs fewer
    _refused(_file(maneuver), f"dec_lstm.w_ih is not a finite float array of shape {shape}")


def test_files_and_cards_are_found_or_refused_by_name(tmp_path, params):
    model = model_from_params(False, params)
    path = tmp_path / "w.msgpack"
    save_weights(path, model)
    assert not (tmp_path / "w.json").exists()  # no card asked for, none written
    np.testing.assert_array_equal(np.asarray(load_weights(path).op.bias), params["op"]["bias"])
    with pytest.raises(InputError, match=f"^weight file not found: {tmp_path / 'none.msgpack'}$"):
        load_weights(tmp_path / "none.msgpack")
    with pytest.raises(InputError, match=f"^cannot read weight file {tmp_path}: "):
        load_weights(tmp_path)  # a folder
    (tmp_path / "w.json").write_text("{not json")
    with pytest.raises(InputError, match=f"^cannot read model card {tmp_path / 'w.json'}: "):
        read_card(path)
    (tmp_path / "w.json").write_text(json.dumps({"validation": {"rmse_m": {"cslstm": [1, 2.5]}}}))
    assert load_predictor(path).validation_rmse_m == (1.0, 2.5)
    (tmp_path / "w.json").write_text(json.dumps({"validation": {}}))
    assert load_predictor(path).validation_rmse_m is None


def test_a_checkpoint_s_predictor_carries_the_published_rmse(tmp_path, monkeypatch, params):
    import _torch_zip

    _torch_zip.write(tmp_path / "c.tar", state_dict_from_model(model_from_params(False, params)))
    assert load_predictor(tmp_path / "c.tar").validation_rmse_m == (0.61, 1.27, 2.09, 3.10, 4.37)
    monkeypatch.setattr(_api, "DEFAULT_WEIGHTS", tmp_path / "none.msgpack")
    with pytest.raises(InputError, match=f"^no shipped weights at {tmp_path / 'none.msgpack'}: train them"):
        load_predictor()


def test_torch_layouts_are_the_transposes(params):
    sd = state_dict_from_model(model_from_params(False, params))
    np.testing.assert_array_equal(sd["op.weight"], params["op"]["weight"].T)  # [out, in]
    np.testing.assert_array_equal(sd["enc_lstm.weight_ih_l0"], params["enc_lstm"]["w_ih"].T)  # [4H, in]
    np.testing.assert_array_equal(sd["enc_lstm.weight_hh_l0"], params["enc_lstm"]["w_hh"].T)
    np.testing.assert_array_equal(sd["dec_lstm.bias_hh_l0"], params["dec_lstm"]["b_hh"])
    kernel = params["soc_conv"]["kernel"]  # HWIO
    for o, i, h, w in np.ndindex(*sd["soc_conv.weight"].shape):  # OIHW
        assert sd["soc_conv.weight"][o, i, h, w] == kernel[h, w, i, o]
    back = state_dict_from_model(model_from_state_dict(sd))
    assert all(np.array_equal(back[k], v) and back[k].flags.c_contiguous for k, v in sd.items())


def test_a_state_dict_is_refused_with_the_first_fault(params):
    sd = state_dict_from_model(model_from_params(False, params))
    for n_in, reason in ((100, "100 input columns"), (0, "0 input columns")):
        bad = sd | {"dec_lstm.weight_ih_l0": np.zeros((512, n_in), np.float32)}
        with pytest.raises(InputError, match=f"^ckpt: dec_lstm.weight_ih_l0 has {reason}; CS-LSTM has 112 "
                                             r"\(single-mode\) or 117 \(manoeuvre\)$"):
            model_from_state_dict(bad, "ckpt")
    missing = {k: v for k, v in sd.items() if k != "dec_lstm.weight_ih_l0"}
    with pytest.raises(InputError, match="has 0 input columns"):
        model_from_state_dict(missing, "ckpt")
    cases = {
        "ckpt: not a CS-LSTM state_dict (missing key op.bias)": {k: v for k, v in sd.items() if k != "op.bias"},
        "ckpt: not a CS-LSTM state_dict (unexpected key a.b)": sd | {"z.z": sd["op.bias"],
                                                                     "a.b": np.zeros(1, np.float32)},
        "ckpt: op.bias has shape (4,), expected (5,)": sd | {"op.bias": np.zeros(4, np.float32)},
        "ckpt: op.bias contains NaN or inf": sd | {"op.bias": np.array([0, 0, 0, 0, np.inf], np.float32)},
    }
    for reason, bad in cases.items():
        with pytest.raises(InputError) as info:
            model_from_state_dict(bad, "ckpt")
        assert str(info.value) == reason


def test_weights_are_saved_as_float32_whatever_the_network_runs_in(tmp_path):
    import jax.numpy as jnp

    from diffsense.predictors import init_predictor

    model64 = init_predictor().model(jnp.float64)
    assert np.asarray(model64.op.bias).dtype == np.float64
    save_weights(tmp_path / "w.msgpack", model64, {"note": "x"})
    tree = serialization.msgpack_restore((tmp_path / "w.msgpack").read_bytes())
    assert {np.asarray(v).dtype for group in tree["params"].values() for v in group.values()} == {np.dtype(np.float32)}
    assert read_card(tmp_path / "w.msgpack") == {"note": "x"}


def test_conversion_is_float32_both_ways():
    import jax.numpy as jnp

    from diffsense.predictors import init_predictor

    sd = state_dict_from_model(init_predictor().model(jnp.float64))
    assert {v.dtype for v in sd.values()} == {np.dtype(np.float32)}
    model = model_from_state_dict({k: v.astype(np.float64) for k, v in sd.items()})
    assert np.asarray(model.dec_lstm.w_ih).dtype == np.float32


def test_a_state_dict_s_default_source_and_a_flat_decoder_weight():
    with pytest.raises(InputError, match=r"^checkpoint: dec_lstm.weight_ih_l0 has 50 input columns; "):
        model_from_state_dict({"dec_lstm.weight_ih_l0": np.zeros(50, np.float32)})
