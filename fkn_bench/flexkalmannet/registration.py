"""Registers ``flexkalmannet``, ``flexkalmannet-rigid-body`` and ``flexkalmannet-tv`` with the estimator
registry (imported lazily by the registry); their committed parameter files are this package's
``params/<name>-<family>.json`` (and ``.weights.pt``)."""

from __future__ import annotations

from fkn_bench.estimators.registry import register_estimator
from fkn_bench.flexkalmannet.checkpoint import RIGID_BODY_TRAINABLE, TIME_VARYING_TRAINABLE, TRAINABLE
from fkn_bench.flexkalmannet.estimator import FlexKalmanNetEstimator, flexkalmannet_factory, flexkalmannet_tv_factory
from fkn_bench.training.artifacts import artifact_factory

__all__: list[str] = []

PARAMS_PACKAGE = "fkn_bench.flexkalmannet"
"""The package whose ``params/`` holds the committed parameter files of these estimators."""

register_estimator(
    "flexkalmannet",
    flexkalmannet_factory,
    description="FlexKalmanNet: EKF with noise parameters learned by a fully connected network",
    trainable=TRAINABLE,
    params_package=PARAMS_PACKAGE,
)
register_estimator(
    "flexkalmannet-rigid-body",
    artifact_factory("flexkalmannet-rigid-body", FlexKalmanNetEstimator),
    description="FlexKalmanNet through the torque-free rigid-body model with estimated inertia ratios",
    trainable=RIGID_BODY_TRAINABLE,
    params_package=PARAMS_PACKAGE,
)
register_estimator(
    "flexkalmannet-tv",
    flexkalmannet_tv_factory,
    description="FlexKalmanNet, time-varying: per-step noise from the network's outputs on recent measurements",
    trainable=TIME_VARYING_TRAINABLE,
    params_package=PARAMS_PACKAGE,
)
