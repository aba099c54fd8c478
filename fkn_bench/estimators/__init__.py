"""The estimator API (:class:`Estimator`), its registry, and the built-in Kalman estimators."""

from fkn_bench.estimators.base import (
    Estimate,
    Estimates,
    Estimator,
    EstimatorFileError,
    RecursiveEstimator,
    check_batch_inputs,
    check_dt,
    parse_observation,
)
from fkn_bench.estimators.kalman import KalmanEstimator
from fkn_bench.estimators.registry import (
    ENTRY_POINT_GROUP,
    EstimatorSpec,
    UnknownEstimatorError,
    estimator_names,
    estimator_spec,
    estimator_specs,
    load_estimator,
    make_estimator,
    register_estimator,
)

__all__ = [
    "ENTRY_POINT_GROUP",
    "Estimate",
    "Estimates",
    "Estimator",
    "EstimatorFileError",
    "EstimatorSpec",
    "KalmanEstimator",
    "RecursiveEstimator",
    "UnknownEstimatorError",
    "check_batch_inputs",
    "check_dt",
    "estimator_names",
    "estimator_spec",
    "estimator_specs",
    "load_estimator",
    "make_estimator",
    "parse_observation",
    "register_estimator",
]
