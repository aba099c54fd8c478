"""Registers ``kalmannet`` and ``recursive-kalmannet`` with the estimator registry (imported
lazily by the registry)."""

from __future__ import annotations

from fkn_bench.estimators.registry import register_estimator
from fkn_bench.kalmannet.checkpoint import RECURSIVE_TRAINABLE, TRAINABLE
from fkn_bench.kalmannet.estimator import kalmannet_factory, recursive_kalmannet_factory

__all__: list[str] = []

register_estimator(
    "kalmannet",
    kalmannet_factory,
    description="KalmanNet (architecture 2): a recurrent network computes the Kalman gain",
    trainable=TRAINABLE,
)

register_estimator(
    "recursive-kalmannet",
    recursive_kalmannet_factory,
    description="Recursive KalmanNet (Mortada et al. 2025): recurrent networks compute the gain and the error covariance",
    trainable=RECURSIVE_TRAINABLE,
)
