"""The predictor's domain guard: a scene faster than the predictor learnt is flagged; sc01 is not."""

from __future__ import annotations

import pytest

import diffsense as ds
from diffsense._domain import DOMAIN_FACTOR, domain_check, domain_note


@pytest.fixture(scope="module")
def shipped():
    return ds.predictors.load_predictor()


def test_the_shipped_card_gives_the_validation_figures(shipped):
    card = ds.predictors.read_card()
    assert shipped.validation_rmse_m == tuple(card["validation"]["rmse_m"]["cslstm"])


@pytest.mark.slow
def test_guard_fires_on_a_fast_scene_and_not_on_sc01(shipped):
    # sc05 drives at 100 km/h with a +5 km/h cut-in (configs/scenarios/sc05.toml); the shipped
    # predictor's training traffic is slower, and its ground-truth-input error at 5 s is far
    # beyond its card's. sc01 lies inside.
    problem = ds.Problem(scenarios=["sc01", "sc05"], variants=1, prediction_stride_frames=20, predictor=shipped)
    E = ds.objective(problem)
    check = domain_check(E, shipped.validation_rmse_m)
    assert check["outside"] == ["sc05"]
    assert check["scenarios"]["sc01"]["inside"] is True
    card_5s = shipped.validation_rmse_m[-1]
    assert check["scenarios"]["sc05"]["rmse_gt_m"][-1] > DOMAIN_FACTOR * card_5s
    assert check["scenarios"]["sc01"]["rmse_gt_m"][-1] <= DOMAIN_FACTOR * card_5s
    assert "sc05" in domain_note(check) and "sc01" not in domain_note(check)
    unknown = domain_check(E, None)
    assert unknown["outside"] == [] and unknown["scenarios"]["sc05"]["inside"] is None
