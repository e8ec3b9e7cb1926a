"""Objective: E_RMSE(r) (the paper's Eq. 12), its estimators and per-horizon RMSE."""

from diffsense.metrics._build import (
    PAPER_SCENARIOS,
    Problem,
    ProblemConfig,
    build_problem,
    check_interval,
    resolve_param,
    simulate_scenes,
)
from diffsense.metrics._estimators import ESTIMATORS, Estimator, EstimatorConfig, relaxed_bernoulli
from diffsense.metrics._objective import DetectFn, Objective, ObjectiveData, PredictFn, make_objective

__all__ = [
    "PAPER_SCENARIOS", "Problem", "ProblemConfig", "build_problem", "check_interval",
    "resolve_param", "simulate_scenes",
    "ESTIMATORS", "Estimator", "EstimatorConfig", "relaxed_bernoulli",
    "DetectFn", "Objective", "ObjectiveData", "PredictFn", "make_objective",
]
