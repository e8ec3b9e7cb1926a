"""The predictor's domain guard: a scene faster than the predictor learnt is flagged; sc01 is not."""

from __future__ import annotations

import pytest

import diffsense as ds
from diffsense.study import domain_check, domain_note
from tests.conftest import ROOT


@pytest.fixture(scope="module")
def shipped():
    return ds.predictors.load_predictor()


def _faster_scenario(tmp_path, speed_kmh: float) -> str:
    """sc05 (straight road, +5 km/h cut-in) with every variant at `speed_kmh`."""
    text = (ROOT / "configs" / "scenarios" / "sc05.toml").read_text()
    line = next(l for l in text.splitlines() if l.startswith("speed_kmh = "))
    text = text.replace(line, f"speed_kmh = {{ nominal = {speed_kmh}, low = {speed_kmh}, high = {speed_kmh} }}")
    path = tmp_path / "fast.toml"
    path.write_text(text.replace('name = "sc05"', 'name = "fast"'))
    return str(path)


@pytest.mark.slow
def test_guard_fires_on_a_fast_scene_and_not_on_sc01(shipped, tmp_path):
    # 150 km/h is beyond the shipped predictor's training traffic (configs/traffic/default.toml:
    # 95 % of its samples below 115 km/h): its ground-truth-input error at 5 s is far beyond its
    # card's. sc01 (55 km/h) lies inside.
    problem = ds.Problem(scenarios=["sc01", _faster_scenario(tmp_path, 150.0)], variants=1,
                         prediction_stride_frames=20, predictor=shipped)
    E = ds.objective(problem)
    check = domain_check(E, shipped.validation_rmse_m)
    assert check["outside"] == ["fast"]
    assert check["scenarios"]["sc01"]["inside"] is True
    card_5s = shipped.validation_rmse_m[-1]
    assert check["factor"] == 2.0  # outside: beyond twice the card's error at some whole second
    assert check["scenarios"]["fast"]["rmse_gt_m"][-1] > 2.0 * card_5s
    assert check["scenarios"]["sc01"]["rmse_gt_m"][-1] <= 2.0 * card_5s
    assert "fast" in domain_note(check) and "sc01" not in domain_note(check)
    unknown = domain_check(E, None)
    assert unknown["outside"] == [] and unknown["scenarios"]["fast"]["inside"] is None


@pytest.mark.slow
def test_shipped_predictor_covers_every_shipped_scenario():
    """The retraining target: from ground-truth histories, on every shipped scenario (the default
    problem's variants and instants), the error at each whole second is within 1.5x the card's
    validation RMSE there."""
    shipped = ds.predictors.load_predictor()
    check = domain_check(ds.objective(ds.Problem(predictor=shipped)), shipped.validation_rmse_m)
    assert check["outside"] == []
    for name, scenario in check["scenarios"].items():
        ratios = [r / v for r, v in zip(scenario["rmse_gt_m"], shipped.validation_rmse_m)]
        assert max(ratios) <= 1.5, (name, ratios)
