"""The predictor's input contract (`InputSpec`): the CS-LSTM's, what follows from it, and the
specs and scene rates it refuses."""

from __future__ import annotations

import dataclasses

import pytest

from diffsense.tracks import CSLSTM_SPEC, M_PER_FT


def test_the_cslstm_spec_and_what_follows_from_it():
    assert M_PER_FT == 0.3048  # the international foot, exactly
    s = CSLSTM_SPEC
    assert (s.history_points, s.future_points, s.rate_hz, s.grid_cells, s.grid_lanes) == (16, 25, 5.0, 13, 3)
    assert s.grid_cell_m == pytest.approx(4.572, abs=1e-12)  # 15 ft
    assert s.history_s == 3.0 and s.future_s == 5.0 and s.grid_size == 39
    assert s.grid_half_length_m == pytest.approx(29.718, abs=1e-12)  # 6.5 cells of 15 ft
    assert s.frames_per_point(0.1) == 2 and s.frames_per_point(0.2) == 1 and s.frames_per_point(0.04) == 5
    horizon = s.horizon_s()
    assert len(horizon) == 25 and horizon[0] == 0.2 and horizon[4] == 1.0 and horizon[-1] == 5.0


@pytest.mark.parametrize("scene_dt_s", [0.3, 0.15, 0.5])
def test_a_scene_rate_that_is_not_a_multiple_of_the_predictors_is_refused(scene_dt_s):
    with pytest.raises(ValueError, match="5 Hz predictor"):
        CSLSTM_SPEC.frames_per_point(scene_dt_s)


@pytest.mark.parametrize("field, value", [("history_points", 0), ("future_points", 0), ("grid_cells", 0),
                                          ("grid_lanes", 0), ("rate_hz", 0.0), ("rate_hz", float("inf")),
                                          ("rate_hz", -5.0), ("grid_cell_m", 0.0)])
def test_a_spec_with_an_empty_or_non_positive_field_is_refused(field, value):
    with pytest.raises(ValueError, match=field):
        dataclasses.replace(CSLSTM_SPEC, **{field: value})


def test_a_spec_at_the_smallest_allowed_values():
    ok = dataclasses.replace(CSLSTM_SPEC, history_points=1, future_points=1, grid_cells=1, grid_lanes=1)
    assert ok.history_s == 0.0 and ok.grid_size == 1
    slow = dataclasses.replace(CSLSTM_SPEC, rate_hz=0.5, grid_cell_m=0.5)  # below 1 but positive: fine
    assert slow.future_s == 50.0 and slow.grid_half_length_m == 3.25
