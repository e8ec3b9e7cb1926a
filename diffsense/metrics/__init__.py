"""Metrics: E_RMSE(r) (the paper's Eq. 12) as a pure equinox Module, its estimators, and the
per-horizon RMSE of both predictions against the true future.

`pad_vehicles(scene, width)` pads a batch's vehicle axis with absent cars, so that scenes of
different vehicle counts pool into one `make_objective` batch.

Intervals from the scene sample (`_intervals.py`): `scene_sums` of an evaluation, then
`bootstrap_ci` (E), `difference_ci` (E(a) - E(b), paired) and `argmin_ci` (the minimiser over
evaluated points) reweight them, and `part_sums` / `part_cis` the breakdown's parts likewise
(`_part_intervals.py`); all over stratified
resamples of the variants (`bootstrap_counts`); `with_variants(E, index)` is E over a resample's
variants, evaluated afresh.
"""

from diffsense.metrics._breakdown import breakdown, drawn_breakdown, drawn_tracked_summary, tracked_summary
from diffsense.metrics._build import (
    PAPER_SCENARIOS,
    SpeedShiftedScenes,
    make_objective,
    recorded_scenes,
    relevance_reach,
    simulate_scenes,
    speed_shifted_scenes,
    with_scenes,
    with_variants,
)
from diffsense.metrics._build import pad_vehicles
from diffsense.metrics._cost import (
    CostModel,
    CostTerm,
    SensorCost,
    cost_breakdown,
    load_costs,
    make_cost,
    member_costs,
)
from diffsense.metrics._coverage import COVERAGE_PARTS, coverage_parts
from diffsense.metrics._datatypes import HardEvaluation, ObjectiveData
from diffsense.metrics._estimators import (
    ESTIMATORS,
    Estimator,
    EstimatorConfig,
    relaxed_bernoulli,
)
from diffsense.metrics._grad import value_and_grad
from diffsense.metrics._intervals import (
    LEVEL,
    RESAMPLES,
    SceneSums,
    argmin_ci,
    bootstrap_ci,
    bootstrap_counts,
    difference_ci,
    estimable,
    expanded_tail,
    scene_sums,
)
from diffsense.metrics._objective import QUESTIONS, Objective
from diffsense.metrics._part_intervals import (
    PartSums,
    drawn_part_sums,
    hard_part_sums,
    part_cis,
    part_sums,
    with_part_cis,
)
from diffsense.metrics._reference import (
    DrawnParts,
    ReferenceEvaluation,
    is_deterministic,
    reference_draw_margins,
    safe_sqrt,
)

__all__ = [
    "COVERAGE_PARTS", "ESTIMATORS", "PAPER_SCENARIOS", "QUESTIONS", "CostModel", "CostTerm", "DrawnParts", "Estimator",
    "EstimatorConfig", "HardEvaluation", "Objective", "ObjectiveData", "ReferenceEvaluation", "SensorCost",
    "SpeedShiftedScenes", "breakdown", "cost_breakdown", "drawn_breakdown", "drawn_tracked_summary", "coverage_parts", "is_deterministic", "load_costs",
    "make_cost", "make_objective", "member_costs", "pad_vehicles", "recorded_scenes", "reference_draw_margins", "relaxed_bernoulli",
    "relevance_reach", "safe_sqrt", "simulate_scenes", "speed_shifted_scenes", "tracked_summary", "value_and_grad",
    "with_scenes", "with_variants", "LEVEL", "RESAMPLES", "SceneSums", "argmin_ci", "bootstrap_ci", "bootstrap_counts",
    "difference_ci", "estimable", "expanded_tail", "scene_sums", "PartSums", "drawn_part_sums",
    "hard_part_sums", "part_cis", "part_sums", "with_part_cis",
]
