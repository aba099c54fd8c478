"""Registers ``flexkalmannet`` with the estimator registry (imported lazily by the registry)."""

from __future__ import annotations

from typing import Any

from fkn_bench.estimators.registry import register_estimator
from fkn_bench.flexkalmannet.checkpoint import TRAINABLE
from fkn_bench.scenarios import Scenario

__all__: list[str] = []


def _factory(scenario: Scenario | None = None, **options: Any) -> Any:
    from fkn_bench.flexkalmannet.estimator import flexkalmannet_factory

    return flexkalmannet_factory(scenario, **options)


register_estimator(
    "flexkalmannet",
    _factory,
    description="FlexKalmanNet: EKF with noise parameters learned by a fully connected network",
    trainable=TRAINABLE,
)
