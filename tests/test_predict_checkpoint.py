"""Loading weights without torch: the published zip format through a restricted unpickler, and
the project's own msgpack files; everything that is not one of them is one clear InputError."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest

import _torch_zip
from diffsense.runtime._errors import InputError
from diffsense.predictors import (
    load_predictor,
    load_weights,
    read_card,
    read_state_dict,
    save_weights,
    state_dict_from_model,
)
from diffsense.predictors import _api
from diffsense.predictors._model import model_from_params, param_shapes


def _model(maneuvers: bool):
    rng = np.random.default_rng(int(maneuvers))
    params = {
        k: {kk: rng.uniform(-0.3, 0.3, size=vv).astype(np.float32) for kk, vv in v.items()}
        for k, v in param_shapes(maneuvers).items()
    }
    return model_from_params(maneuvers, params)


@pytest.fixture(scope="module", params=[False, True], ids=["single", "maneuver"])
def state_dict(request):
    return state_dict_from_model(_model(request.param))


def test_round_trip_through_the_torch_format(tmp_path, state_dict):
    path = tmp_path / "ckpt.tar"
    _torch_zip.write(path, state_dict)
    got = read_state_dict(path)
    assert list(got) == list(state_dict)
    for key in state_dict:
        assert np.array_equal(got[key], state_dict[key]), key
    predictor = load_predictor(path)
    assert predictor.maneuvers == (state_dict["dec_lstm.weight_ih_l0"].shape[1] == 117)
    assert state_dict_from_model(predictor.model()).keys() == state_dict.keys()


@pytest.mark.parametrize(
    "name, count, maneuvers",
    [("cslstm_no_m.tar", 192_394, False), ("cslstm_m.tar", 194_954, True)],
)
def test_published_checkpoints_load(ngsim_checkpoint, name, count, maneuvers):
    sd = read_state_dict(ngsim_checkpoint(name))
    assert sum(v.size for v in sd.values()) == count
    assert all(v.dtype == np.float32 for v in sd.values())
    assert load_predictor(ngsim_checkpoint(name)).maneuvers is maneuvers


def _one_line_error(fn, *needles):
    with pytest.raises(InputError) as info:
        fn()
    msg = str(info.value)
    assert "\n" not in msg
    for needle in needles:
        assert needle in msg, msg
    return msg


def test_tampered_pickle_is_refused_and_never_runs(tmp_path, state_dict):
    marker = tmp_path / "pwned"
    path = tmp_path / "evil.tar"
    _torch_zip.write(path, state_dict, extra_global=("posix", "system", f"touch {marker}"))
    _one_line_error(lambda: read_state_dict(path), "refused global posix.system")
    _one_line_error(lambda: load_predictor(path), "refused")
    assert not marker.exists()
    path2 = tmp_path / "evil2.tar"
    _torch_zip.write(path2, state_dict, extra_global=("builtins", "eval", "1+1"))
    _one_line_error(lambda: read_state_dict(path2), "refused global builtins.eval")


def test_malformed_files_are_refused(tmp_path, state_dict):
    _one_line_error(lambda: load_predictor(tmp_path / "missing.tar"), "not found")
    (tmp_path / "text.tar").write_text("not a zip")
    _one_line_error(lambda: load_predictor(tmp_path / "text.tar"), "not a zip")
    with zipfile.ZipFile(tmp_path / "empty.tar", "w") as z:
        z.writestr("x/readme", "hi")
    _one_line_error(lambda: load_predictor(tmp_path / "empty.tar"), "data.pkl")
    # A storage shorter than the tensor it claims.
    short = tmp_path / "short.tar"
    _torch_zip.write(short, state_dict)
    with zipfile.ZipFile(short) as z:
        files = {n: z.read(n) for n in z.namelist()}
    files["archive/data/0"] = files["archive/data/0"][:-4]
    with zipfile.ZipFile(short, "w") as z:
        for n, b in files.items():
            z.writestr(n, b)
    _one_line_error(lambda: load_predictor(short), "storage 0")
    # Truncated pickle.
    trunc = tmp_path / "trunc.tar"
    with zipfile.ZipFile(trunc, "w") as z:
        z.writestr("archive/data.pkl", _torch_zip.pickle_bytes(state_dict)[:-40])
    _one_line_error(lambda: load_predictor(trunc), "refused")


def test_wrong_keys_and_shapes_are_refused(tmp_path, state_dict):
    cases = {
        "extra": ({**state_dict, "soc_fc.weight": np.zeros((2, 2), np.float32)}, "unexpected key soc_fc.weight"),
        "missing": ({k: v for k, v in state_dict.items() if k != "op.bias"}, "missing key op.bias"),
        "shape": ({**state_dict, "op.weight": np.zeros((5, 64), np.float32)}, "op.weight has shape"),
        "variant": ({**state_dict, "dec_lstm.weight_ih_l0": np.zeros((512, 100), np.float32)}, "100 input columns"),
        "nan": ({**state_dict, "op.bias": np.full(5, np.nan, np.float32)}, "NaN"),
    }
    for name, (sd, needle) in cases.items():
        path = tmp_path / f"{name}.tar"
        _torch_zip.write(path, sd)
        _one_line_error(lambda: load_predictor(path), needle)


def test_msgpack_round_trip_and_card(tmp_path, state_dict):
    maneuvers = state_dict["dec_lstm.weight_ih_l0"].shape[1] == 117
    model = _model(maneuvers)
    path = tmp_path / "w.msgpack"
    save_weights(path, model, {"steps": 3})
    assert path.stat().st_size < 2_000_000
    again = load_weights(path)
    assert again.maneuvers == maneuvers
    for key, value in state_dict_from_model(model).items():
        assert np.array_equal(state_dict_from_model(again)[key], value)
    assert load_predictor(path).maneuvers == maneuvers
    assert read_card(path) == {"steps": 3}
    (tmp_path / "bad.msgpack").write_bytes(b"\x00garbage")
    _one_line_error(lambda: load_predictor(tmp_path / "bad.msgpack"), "bad.msgpack")


def test_missing_default_weights_say_how_to_train(tmp_path, monkeypatch):
    monkeypatch.setattr(_api, "DEFAULT_WEIGHTS", tmp_path / "none.msgpack")
    _one_line_error(lambda: load_predictor(), "python -m diffsense.train")
    _one_line_error(lambda: read_card(tmp_path / "none.msgpack"), "no model card")
