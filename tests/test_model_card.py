"""The shipped predictor's model card (diffsense/predictors/weights/cslstm.json) says what the
weights next to it are and how well they predict; these tests hold it to its own numbers."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

WEIGHTS = Path(__file__).resolve().parents[1] / "diffsense" / "predictors" / "weights"


@pytest.fixture(scope="module")
def card():
    return json.loads((WEIGHTS / "cslstm.json").read_text())


def test_validation_horizons_are_one_to_five_seconds(card):
    val = card["validation"]
    assert val["horizon_s"] == [1, 2, 3, 4, 5]
    for table in (val["rmse_m"], *val["rmse_by_axis_m"].values()):
        for values in table.values():
            assert len(values) == 5


def test_shipped_predictor_beats_constant_velocity_at_every_horizon(card):
    rmse = card["validation"]["rmse_m"]
    cslstm, cv = np.asarray(rmse["cslstm"]), np.asarray(rmse["constant_velocity"])
    assert np.all(cslstm > 0) and np.all(cv > 0)
    assert np.all(cslstm < cv), (cslstm, cv)
    # Errors grow with the horizon for both (a prediction 5 s out is never better than 1 s out).
    assert np.all(np.diff(cslstm) > 0) and np.all(np.diff(cv) > 0)


def test_total_rmse_is_the_root_sum_of_squares_of_its_axes(card):
    # RMSE of a 2-D error: sqrt(mean(dx^2 + dy^2)) = sqrt(RMSE_lon^2 + RMSE_lat^2), e.g. at 1 s
    # sqrt(0.2032^2 + 0.1378^2) = 0.2455 m. The card rounds to 0.1 mm.
    val = card["validation"]
    for model, total in val["rmse_m"].items():
        axes = val["rmse_by_axis_m"][model]
        np.testing.assert_allclose(np.hypot(axes["lon"], axes["lat"]), total, atol=2e-4)


def test_training_record_is_consistent(card):
    optim = card["train_config"]["optim"]
    history = card["history"]
    assert card["epochs"] == len(history) == optim["mse_epochs"] + optim["nll_epochs"]
    assert [h["phase"] for h in history] == (
        ["mse"] * optim["mse_epochs"] + ["nll"] * optim["nll_epochs"])
    # The validation numbers are those of the last epoch, the weights shipped.
    assert history[-1]["val_rmse_m"] == card["validation"]["rmse_m"]["cslstm"]
    data = card["data"]
    assert data["num_train_samples"] + data["num_val_samples"] == card["train_config"]["data"]["max_samples"]
    # Validation is split by whole simulations: about, not exactly, val_fraction of the samples.
    fraction = data["num_val_samples"] / card["train_config"]["data"]["max_samples"]
    assert fraction == pytest.approx(card["train_config"]["data"]["val_fraction"], abs=0.01)
    assert card["maneuvers"] is card["train_config"]["maneuvers"] is False


def test_parameter_count_matches_the_shipped_weights(card):
    from flax import serialization

    blob = serialization.msgpack_restore((WEIGHTS / "cslstm.msgpack").read_bytes())
    assert blob["maneuvers"] is card["maneuvers"]
    sizes = [int(np.size(leaf)) for layer in blob["params"].values() for leaf in layer.values()]
    assert sum(sizes) == card["parameters"]
    assert math.isfinite(card["wall_time_s"]) and card["wall_time_s"] > 0
