"""r*'s 90 % interval is calibrated where the answer is chosen on E_ref (a probabilistic law, the
physical profile's radar default): over 50 independent seeds of a small problem (radar, sc01 +
sc03, 8 variants each, E_ref on 4 detection draws), `argmin_ci` over E_ref on a 1-deg grid of
HFOV (a re-solve at that resolution on every resample, as the job's own points are made dense
where the picks fall) covers r* re-solved on the same grid with 128 variants per scenario on
another seed in 80-97 % of seeds.

Under the threshold law the interval does not reach this (docs/uncertainty.md): E_hard's minimum
sits where the first far target drops out of range, and no resample of a scene sample holds a
cliff earlier than the sample's own. Every seed's problem has the same shape: one program."""

from __future__ import annotations

import numpy as np
import pytest

import diffsense as ds
from diffsense.metrics import LEVEL, EstimatorConfig, argmin_ci
from diffsense.solve import Evaluator

# The grid spans every seed's interval with room on both sides (checked below): r* lies near 15 deg.
GRID = np.arange(10.0, 22.01, 1.0)
SEEDS = 50


def _sums(seed: int, variants: int):
    problem = ds.Problem(sensor="radar", scenarios=["sc01", "sc03"], variants=variants, seed=seed,
                         params={"hfov": (5.0, 60.0)}, estimator=EstimatorConfig(reference_draws=4))
    E = ds.objective(problem)
    ev = Evaluator(E)
    return [ev.scene_sums(float(r), of_reference=True) for r in GRID], np.asarray(E.data.scenario)


@pytest.fixture(scope="module")
def outcome():
    """The large-sample r*, and each seed's interval."""
    big, groups = _sums(10_000, 128)
    ones = np.ones((1, groups.size))
    truth = float(GRID[np.argmin([float(s.e(ones)[0]) for s in big])])
    intervals = []
    for seed in range(SEEDS):
        sums, strata = _sums(seed, 8)
        intervals.append(argmin_ci(GRID, sums, strata, level=LEVEL, seed=seed))
    return truth, intervals


@pytest.mark.slow
def test_r_star_s_90_percent_interval_covers_the_large_sample_r_star_in_80_to_97_percent_of_seeds(outcome):
    truth, intervals = outcome
    assert GRID[0] < truth < GRID[-1]
    # no interval is cut by the grid's ends: a wider grid would give the same picks
    assert all(GRID[0] < lo <= hi < GRID[-1] for lo, hi in intervals), intervals
    coverage = float(np.mean([lo <= truth <= hi for lo, hi in intervals]))
    assert LEVEL == 0.9 and 0.80 <= coverage <= 0.97, f"coverage {coverage:.2f} over {SEEDS} seeds"
