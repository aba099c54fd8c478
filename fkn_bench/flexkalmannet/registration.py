"""Registers ``flexkalmannet`` with the estimator registry (imported lazily by the registry)."""

from __future__ import annotations

from fkn_bench.estimators.registry import register_estimator
from fkn_bench.flexkalmannet.checkpoint import TRAINABLE
from fkn_bench.flexkalmannet.estimator import flexkalmannet_factory

__all__: list[str] = []

register_estimator(
    "flexkalmannet",
    flexkalmannet_factory,
    description="FlexKalmanNet: EKF with noise parameters learned by a fully connected network",
    trainable=TRAINABLE,
)
