"""`diffsense predict parity|card` (`python -m diffsense.predictors`): reference-layout outputs of
both published checkpoints against the numpy forward; bad input is one line naming its culprit
and exit code 2, nothing written."""

from __future__ import annotations

import json
import subprocess
import sys

import _numpy_cslstm
import _torch_zip
import numpy as np
import pytest

from diffsense import cli as _cli
from diffsense.cli.predict import main
from diffsense.predictors import init_predictor, read_state_dict, save_weights, state_dict_from_model


def _run(argv: list[str]) -> int:
    with pytest.raises(SystemExit) as info:
        _cli.run(lambda: main(argv))
    return info.value.code


def _write_inputs(path, seed: int = 0, b: int = 4):
    rng = np.random.default_rng(seed)
    mask = np.zeros((b, 3, 13, 64), bool)
    for row in range(b):
        slots = rng.choice([s for s in range(39) if s != 19], size=3 + row, replace=False)
        mask[row].reshape(39, 64)[slots] = True
    n = int(mask[..., 0].sum())
    hist = (rng.normal(size=(16, b, 2)) * [2.0, 30.0]).astype(np.float32)
    nbrs = (rng.normal(size=(16, n, 2)) * [12.0, 60.0]).astype(np.float32)
    np.savez(path, hist=hist, nbrs=nbrs, mask=mask)
    return hist, nbrs, mask


@pytest.fixture(scope="module")
def generated_checkpoint(tmp_path_factory):
    """Path factory for a checkpoint in the published files' format and layout, written here
    from a randomly initialised network (so these tests need no ../shared)."""

    def get(name: str):
        path = tmp_path_factory.mktemp("ckpt") / name
        model = init_predictor(maneuvers=name == "cslstm_m.tar", seed=3).model()
        _torch_zip.write(path, state_dict_from_model(model))
        return path

    return get


@pytest.mark.parametrize("source", ["published", "generated"])
@pytest.mark.parametrize("name", ["cslstm_no_m.tar", "cslstm_m.tar"])
def test_parity_cli_matches_numpy_forward(ngsim_checkpoint, generated_checkpoint, tmp_path, capsys, name, source):
    ckpt = (ngsim_checkpoint if source == "published" else generated_checkpoint)(name)
    hist, nbrs, mask = _write_inputs(tmp_path / "in.npz")
    out = tmp_path / "out.npz"
    assert _run(["parity", "--checkpoint", str(ckpt), "--inputs", str(tmp_path / "in.npz"), "--out", str(out)]) == 0
    want = _numpy_cslstm.forward(read_state_dict(ckpt), hist, nbrs, mask)
    got = np.load(out)
    # float32 network vs float64 numpy: agreement to float32 rounding (the published networks'
    # outputs reach ~100 ft; a random initialisation's stay near 1).
    atol = 2e-4 if source == "published" else 2e-6
    if name == "cslstm_m.tar":
        assert got["fut_pred"].shape == (6, 25, 4, 5)
        np.testing.assert_allclose(got["fut_pred"], np.stack(want[0]), rtol=2e-5, atol=atol)
        np.testing.assert_allclose(got["lat_pred"], want[1], rtol=2e-5, atol=1e-6)
        np.testing.assert_allclose(got["lon_pred"], want[2], rtol=2e-5, atol=1e-6)
    else:
        assert set(got.files) == {"fut_pred"} and got["fut_pred"].shape == (25, 4, 5)
        np.testing.assert_allclose(got["fut_pred"], want, rtol=2e-5, atol=atol)
    assert "wrote" in capsys.readouterr().out


def test_parity_cli_bad_inputs(tmp_path, capsys, generated_checkpoint):
    ckpt = str(generated_checkpoint("cslstm_no_m.tar"))
    hist, nbrs, mask = _write_inputs(tmp_path / "in.npz")
    np.savez(tmp_path / "short.npz", hist=hist, nbrs=nbrs[:, :-1], mask=mask)
    np.savez(tmp_path / "nan.npz", hist=np.full_like(hist, np.nan), nbrs=nbrs, mask=mask)
    np.savez(tmp_path / "nomask.npz", hist=hist, nbrs=nbrs)
    out = tmp_path / "out.npz"
    cases = [
        ("short.npz", "short.npz: nbrs"),
        ("nan.npz", "nan.npz: hist"),
        ("nomask.npz", "'mask'"),
        ("absent.npz", "absent.npz"),
    ]
    for name, needle in cases:
        args = ["parity", "--checkpoint", ckpt, "--inputs", str(tmp_path / name), "--out", str(out)]
        assert _run(args) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("error:") and needle in err and "\n" not in err, err
        assert not out.exists()


def test_cli_exit_code_two_in_a_real_process(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "diffsense.predictors", "parity", "--checkpoint", str(tmp_path / "no.tar"),
         "--inputs", str(tmp_path / "in.npz"), "--out", str(tmp_path / "out.npz")],
        capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0 and proc.stderr.startswith("error:"), proc.stderr
    proc = subprocess.run([sys.executable, "-m", "diffsense.predictors", "frobnicate"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and proc.stderr.startswith("error:"), proc.stderr


def test_card_prints_the_model_card(tmp_path, capsys):
    path = tmp_path / "w.msgpack"
    save_weights(path, init_predictor().model(), {"steps": 7, "validation": {"horizon_s": [1, 2]}})
    assert _run(["card", "--weights", str(path)]) == 0
    assert json.loads(capsys.readouterr().out) == {"steps": 7, "validation": {"horizon_s": [1, 2]}}
    assert _run(["card", "--weights", str(tmp_path / "none.msgpack")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "none" in err
