"""Registers the five baselines of :mod:`fkn_bench.baselines` with the estimator registry
(imported lazily by the registry)."""

from __future__ import annotations

from functools import partial
from typing import Any

from fkn_bench.baselines.akhlaghi import AkhlaghiEstimator
from fkn_bench.baselines.sage_husa import SageHusaEstimator
from fkn_bench.baselines.tuned import DESCRIPTIONS, TUNED_OBJECTIVES, TunedEKFEstimator, tuned_trainable
from fkn_bench.baselines.vbakf import VBAKFEstimator
from fkn_bench.estimators.registry import register_estimator
from fkn_bench.scenarios import Scenario
from fkn_bench.training.artifacts import artifact_factory

__all__: list[str] = []


def _adaptive(cls: type, scenario: Scenario | None = None, **options: Any) -> Any:
    return cls(**options)


for _cls, _description in (
    (SageHusaEstimator, "Sage-Husa adaptive EKF: forgetting factor 0.99, R by innovation covariance matching, eigenvalue clamping"),
    (AkhlaghiEstimator, "Adaptive EKF of Akhlaghi, Zhou & Huang 2017: alpha 0.3, residual-based R, innovation-based Q"),
    (VBAKFEstimator, "Variational Bayesian adaptive EKF of Huang et al. 2018 (TAC 63(2)): inverse-Wishart P- and R, 10 iterations"),
):
    register_estimator(_cls.name, partial(_adaptive, _cls), description=_description)
for _name in TUNED_OBJECTIVES:
    register_estimator(
        _name,
        artifact_factory(_name, TunedEKFEstimator),
        description=DESCRIPTIONS[_name],
        trainable=tuned_trainable(_name),
    )
