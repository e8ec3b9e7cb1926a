"""The predictor's weights on disk: the project's msgpack files (float32 whatever the network runs
in, every malformed file one InputError naming it), the PyTorch `state_dict` layout (the
transposes written out element by element, every mismatch named by its key), and the shipped
weights' model card held to its own numbers."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest
from flax import serialization

from diffsense.predictors import (
    DEFAULT_WEIGHTS,
    init_predictor,
    load_weights,
    model_from_state_dict,
    read_card,
    save_weights,
    state_dict_from_model,
)
from diffsense.runtime import InputError

FORMAT = {"format": "diffsense-cslstm", "version": 1}  # the file layout, written out


@pytest.fixture(scope="module", params=[False, True], ids=["single", "maneuver"])
def model(request):
    return init_predictor(request.param, seed=5).model()


def _tree(model, tmp_path) -> dict:
    """A saved weight file's contents as a plain tree."""
    save_weights(tmp_path / "w.msgpack", model)
    return serialization.msgpack_restore((tmp_path / "w.msgpack").read_bytes())


def _refused(tmp_path, tree_or_bytes, *culprits) -> None:
    data = tree_or_bytes if isinstance(tree_or_bytes, bytes) else serialization.msgpack_serialize(tree_or_bytes)
    path = tmp_path / "bad.msgpack"
    path.write_bytes(data)
    with pytest.raises(InputError) as info:
        load_weights(path)
    msg = str(info.value)
    assert "\n" not in msg and str(path) in msg, msg
    assert all(c in msg for c in culprits), msg


def test_a_weight_file_round_trips_in_float32_with_its_card(tmp_path, model):
    model64 = init_predictor(model.maneuvers, seed=5).model(jnp.float64)
    assert np.asarray(model64.op.bias).dtype == np.float64
    path = tmp_path / "w.msgpack"
    save_weights(path, model64, {"steps": 3})
    assert path.stat().st_size < 2_000_000 and read_card(path) == {"steps": 3}
    tree = serialization.msgpack_restore(path.read_bytes())
    assert {k: tree[k] for k in FORMAT} == FORMAT and tree["maneuvers"] is model.maneuvers
    assert {np.asarray(v).dtype for group in tree["params"].values() for v in group.values()} == {np.dtype(np.float32)}
    again = load_weights(path)
    assert again.maneuvers is model.maneuvers
    want, got = state_dict_from_model(model), state_dict_from_model(again)
    assert got.keys() == want.keys() and all(np.array_equal(got[k], want[k]) for k in want)


def test_a_hand_made_weight_file_loads_as_written(tmp_path):
    tree = _tree(init_predictor(seed=5).model(), tmp_path)
    params = {k: {kk: np.asarray(vv) + 0.25 for kk, vv in v.items()} for k, v in tree["params"].items()}  # float64
    path = tmp_path / "hand.msgpack"
    path.write_bytes(serialization.msgpack_serialize(FORMAT | {"maneuvers": False, "params": params}))
    loaded = load_weights(path)
    for name, group in params.items():
        for key, value in group.items():
            got = np.asarray(getattr(getattr(loaded, name), key))
            assert got.dtype == np.float32
            np.testing.assert_array_equal(got, value.astype(np.float32))


def test_the_format_and_version_must_be_the_projects(tmp_path):
    tree = _tree(init_predictor(seed=5).model(), tmp_path)
    for wrong in (tree | {"format": "other"}, tree | {"version": 2}, [1, 2]):
        _refused(tmp_path, wrong, "diffsense-cslstm")
    _refused(tmp_path, b"\xc1", "msgpack")


def test_every_group_and_array_must_match_the_network(tmp_path):
    tree = _tree(init_predictor(seed=5).model(), tmp_path)
    params = tree["params"]
    for groups in ([1], {k: v for k, v in params.items() if k != "op"}, params | {"extra": {"w": np.zeros(2, np.float32)}}):
        _refused(tmp_path, tree | {"params": groups}, "groups")
    for op in ([1], {"weight": params["op"]["weight"]}):
        _refused(tmp_path, tree | {"params": params | {"op": op}}, "op")
    for bias in (np.zeros(6, np.float32), params["op"]["bias"].astype(np.int32), np.full(5, np.nan, np.float32),
                 np.full(5, np.inf, np.float32)):
        _refused(tmp_path, tree | {"params": params | {"op": params["op"] | {"bias": bias}}}, "op.bias")


def test_the_variant_comes_from_the_file(tmp_path):
    tree = _tree(init_predictor(maneuvers=True, seed=5).model(), tmp_path)
    assert load_weights(tmp_path / "w.msgpack").maneuvers is True
    _refused(tmp_path, tree | {"maneuvers": False}, "dec_lstm.w_ih")  # single-mode: 5 decoder inputs fewer


def test_files_and_cards_are_found_or_refused_by_name(tmp_path):
    for path in (tmp_path / "none.msgpack", tmp_path):  # nothing there, a folder
        with pytest.raises(InputError, match=str(path)):
            load_weights(path)
    save_weights(tmp_path / "w.msgpack", init_predictor().model())
    with pytest.raises(InputError, match=str(tmp_path / "w.json")):
        read_card(tmp_path / "w.msgpack")  # no card
    (tmp_path / "w.json").write_text("{not json")
    with pytest.raises(InputError, match=str(tmp_path / "w.json")):
        read_card(tmp_path / "w.msgpack")


def test_torch_layouts_are_the_transposes(model):
    # PyTorch Linear [out, in], LSTM [4H, in] and Conv2d OIHW against ours [in, out], [in, 4H], HWIO.
    sd = state_dict_from_model(model)
    np.testing.assert_array_equal(sd["op.weight"], np.asarray(model.op.weight).T)
    np.testing.assert_array_equal(sd["enc_lstm.weight_ih_l0"], np.asarray(model.enc_lstm.w_ih).T)
    np.testing.assert_array_equal(sd["enc_lstm.weight_hh_l0"], np.asarray(model.enc_lstm.w_hh).T)
    np.testing.assert_array_equal(sd["dec_lstm.bias_hh_l0"], np.asarray(model.dec_lstm.b_hh))
    kernel = np.asarray(model.soc_conv.kernel)
    for o, i, h, w in np.ndindex(*sd["soc_conv.weight"].shape):
        assert sd["soc_conv.weight"][o, i, h, w] == kernel[h, w, i, o]
    back = state_dict_from_model(model_from_state_dict(sd))
    assert all(np.array_equal(back[k], v) and back[k].flags.c_contiguous for k, v in sd.items())
    # float32 both ways, whatever the network runs in or the state_dict holds
    assert {v.dtype for v in state_dict_from_model(init_predictor().model(jnp.float64)).values()} == {np.dtype(np.float32)}
    assert np.asarray(model_from_state_dict({k: v.astype(np.float64) for k, v in sd.items()}).dec_lstm.w_ih).dtype == np.float32


def test_a_state_dict_that_is_not_a_cslstm_is_refused_naming_its_key():
    sd = state_dict_from_model(init_predictor().model())
    cases = [
        (sd | {"dec_lstm.weight_ih_l0": np.zeros((512, 100), np.float32)}, ("dec_lstm.weight_ih_l0", "100")),
        ({k: v for k, v in sd.items() if k != "dec_lstm.weight_ih_l0"}, ("dec_lstm.weight_ih_l0",)),
        ({k: v for k, v in sd.items() if k != "op.bias"}, ("op.bias",)),
        (sd | {"z.z": sd["op.bias"], "a.b": np.zeros(1, np.float32)}, ("a.b",)),  # the first, sorted
        (sd | {"op.bias": np.zeros(4, np.float32)}, ("op.bias", "(4,)")),
        (sd | {"op.bias": np.array([0, 0, 0, 0, np.inf], np.float32)}, ("op.bias",)),
    ]
    for bad, culprits in cases:
        with pytest.raises(InputError) as info:
            model_from_state_dict(bad, "ckpt")
        assert str(info.value).startswith("ckpt: ") and all(c in str(info.value) for c in culprits), info.value
    with pytest.raises(InputError, match="^checkpoint: "):  # the default source
        model_from_state_dict({"dec_lstm.weight_ih_l0": np.zeros(50, np.float32)})


# --- the shipped weights' card ------------------------------------------------------------------

@pytest.fixture(scope="module")
def card():
    return read_card(DEFAULT_WEIGHTS)


def test_the_card_validates_at_one_to_five_seconds_and_beats_constant_velocity(card):
    val = card["validation"]
    assert val["horizon_s"] == [1, 2, 3, 4, 5]
    cslstm, cv = np.asarray(val["rmse_m"]["cslstm"]), np.asarray(val["rmse_m"]["constant_velocity"])
    assert cslstm.shape == cv.shape == (5,) and np.all(cslstm > 0) and np.all(cslstm < cv), (cslstm, cv)
    # Errors grow with the horizon for both (a prediction 5 s out is never better than 1 s out).
    assert np.all(np.diff(cslstm) > 0) and np.all(np.diff(cv) > 0)
    # RMSE of a 2-D error: sqrt(RMSE_lon^2 + RMSE_lat^2); the card rounds to 0.1 mm.
    for model, total in val["rmse_m"].items():
        axes = val["rmse_by_axis_m"][model]
        np.testing.assert_allclose(np.hypot(axes["lon"], axes["lat"]), total, atol=2e-4)


def test_the_cards_training_record_is_consistent(card):
    optim, data, history = card["train_config"]["optim"], card["data"], card["history"]
    assert card["epochs"] == len(history) == optim["mse_epochs"] + optim["nll_epochs"]
    assert [h["phase"] for h in history] == ["mse"] * optim["mse_epochs"] + ["nll"] * optim["nll_epochs"]
    assert history[-1]["val_rmse_m"] == card["validation"]["rmse_m"]["cslstm"]  # the weights shipped
    max_samples = card["train_config"]["data"]["max_samples"]
    assert data["num_train_samples"] + data["num_val_samples"] == max_samples
    # Validation is split by whole simulations: about, not exactly, val_fraction of the samples.
    assert data["num_val_samples"] / max_samples == pytest.approx(card["train_config"]["data"]["val_fraction"], abs=0.01)
    assert card["maneuvers"] is card["train_config"]["maneuvers"] is False
    assert math.isfinite(card["wall_time_s"]) and card["wall_time_s"] > 0
    assert serialization.msgpack_restore(DEFAULT_WEIGHTS.read_bytes())["maneuvers"] is card["maneuvers"]
    assert sum(v.size for v in state_dict_from_model(load_weights(DEFAULT_WEIGHTS)).values()) == card["parameters"]
