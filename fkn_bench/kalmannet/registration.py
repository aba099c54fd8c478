"""Registers ``kalmannet``, ``recursive-kalmannet``, ``split-kalmannet`` and ``cholesky-kalmannet``
with the estimator registry (imported lazily by the registry); their committed weights are this
package's ``params/<name>-<family>.json`` and ``.weights.pt``."""

from __future__ import annotations

from fkn_bench.estimators.registry import register_estimator
from fkn_bench.kalmannet.checkpoint import CHOLESKY_TRAINABLE, RECURSIVE_TRAINABLE, SPLIT_TRAINABLE, TRAINABLE
from fkn_bench.kalmannet.estimator import (cholesky_kalmannet_factory, kalmannet_factory, recursive_kalmannet_factory,
                                           split_kalmannet_factory)

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

register_estimator(
    "split-kalmannet",
    split_kalmannet_factory,
    description="Split-KalmanNet (Choi et al. 2023): recurrent networks compute the gain's prior and innovation covariances",
    trainable=SPLIT_TRAINABLE,
    params_package=PARAMS_PACKAGE,
)

register_estimator(
    "cholesky-kalmannet",
    cholesky_kalmannet_factory,
    description="Cholesky-KalmanNet (Ko & Shafieezadeh 2025): the gain's covariances from learned Cholesky factors",
    trainable=CHOLESKY_TRAINABLE,
    params_package=PARAMS_PACKAGE,
)
