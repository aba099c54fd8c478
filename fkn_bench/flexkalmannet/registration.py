"""Registers ``flexkalmannet`` with the estimator registry (imported lazily by the registry)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fkn_bench.estimators.registry import register_estimator
from fkn_bench.scenarios import Scenario

__all__ = ["train_for_cli"]


def _factory(scenario: Scenario | None = None, **options: Any) -> Any:
    from fkn_bench.flexkalmannet.estimator import flexkalmannet_factory

    return flexkalmannet_factory(scenario, **options)


def train_for_cli(
    scenario: Scenario, *, out: Path, options: dict[str, Any], resume: bool = False, progress: bool = True
) -> dict[str, Any]:
    """``fkn-bench train --estimator flexkalmannet``: options are FlexKalmanNetConfig fields
    (``config`` may name a TOML file whose values the other options override)."""
    from fkn_bench.flexkalmannet.config import FlexKalmanNetConfig
    from fkn_bench.flexkalmannet.train import train_flexkalmannet

    options = dict(options)
    path = options.pop("config", None)
    base = FlexKalmanNetConfig.from_toml(path) if path else FlexKalmanNetConfig()
    config = base.replace(**options) if options else base
    outcome = train_flexkalmannet(scenario, config, out=out, resume=resume, progress=progress)
    return {
        "estimator": "flexkalmannet",
        "scenario": scenario.name,
        "out": str(outcome.out),
        "checkpoint": str(outcome.checkpoint),
        "artifact": str(outcome.artifact),
        "epochs_run": len(outcome.history),
        "best_epoch": outcome.best_epoch,
        "seconds": outcome.seconds,
        **outcome.test,
    }


register_estimator(
    "flexkalmannet",
    _factory,
    description="FlexKalmanNet: EKF with noise parameters learned by a fully connected network",
    train=train_for_cli,
)
