"""Objective: E_RMSE(r) (the paper's Eq. 12), its estimators and per-horizon RMSE."""

from diffsense.objective._estimators import ESTIMATORS, Estimator, EstimatorConfig, relaxed_bernoulli
from diffsense.objective._objective import DetectFn, Objective, ObjectiveData, PredictFn, make_objective

__all__ = [
    "ESTIMATORS", "Estimator", "EstimatorConfig", "relaxed_bernoulli",
    "DetectFn", "Objective", "ObjectiveData", "PredictFn", "make_objective",
]
