"""Registers ``kalmannet`` with the estimator registry (imported lazily by the registry)."""

from __future__ import annotations

from fkn_bench.estimators.registry import register_estimator
from fkn_bench.kalmannet.checkpoint import TRAINABLE
from fkn_bench.kalmannet.estimator import kalmannet_factory

__all__: list[str] = []

register_estimator(
    "kalmannet",
    kalmannet_factory,
    description="KalmanNet (architecture 2): a recurrent network computes the Kalman gain (needs checkpoint=PATH)",
    trainable=TRAINABLE,
)
