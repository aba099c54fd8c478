"""Registers ``kalmannet`` and ``recursive-kalmannet`` with the estimator registry (imported
lazily by the registry); their committed weights are this package's ``params/<name>-<family>.json``
and ``.weights.pt``."""

from __future__ import annotations

from fkn_bench.estimators.registry import register_estimator
from fkn_bench.kalmannet.checkpoint import RECURSIVE_TRAINABLE, TRAINABLE
from fkn_bench.kalmannet.estimator import kalmannet_factory, recursive_kalmannet_factory

__all__: list[str] = []

PARAMS_PACKAGE = "fkn_bench.kalmannet"
"""The package whose ``params/`` holds the committed parameter files of these estimators."""

register_estimator(
    "kalmannet",
    kalmannet_factory,
    description="KalmanNet (architecture 2): a recurrent network computes the Kalman gain",
    trainable=TRAINABLE,
    params_package=PARAMS_PACKAGE,
)

register_estimator(
    "recursive-kalmannet",
    recursive_kalmannet_factory,
    description="Recursive KalmanNet (Mortada et al. 2025): recurrent networks compute the gain and the error covariance",
    trainable=RECURSIVE_TRAINABLE,
    params_package=PARAMS_PACKAGE,
)
