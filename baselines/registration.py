"""Registers the five baselines of :mod:`fkn_bench.baselines` with the estimator registry
(imported lazily by the registry); the committed settings of the tuned ones are this package's
``params/<name>-<family>.json``."""

from __future__ import annotations

from functools import partial
from typing import Any

from fkn_bench.baselines.akhlaghi import AkhlaghiEstimator
from fkn_bench.baselines.sage_husa import SageHusaEstimator
from fkn_bench.baselines.tuned import DESCRIPTIONS, TUNED_OBJECTIVES, TunedEKFEstimator, tuned_trainable
from fkn_bench.baselines.vbakf import VBAKFEstimator
from fkn_bench.estimators.registry import register_estimator
from fkn_bench.scenarios import Scenario
from fkn_bench.training.artifacts import ArtifactError, artifact_factory, committed_artifact, read_artifact

__all__: list[str] = []

PARAMS_PACKAGE = "fkn_bench.baselines"
"""The package whose ``params/`` holds the committed settings of the tuned estimators."""


def _adaptive(cls: type, name: str, description: str, scenario: Scenario | None = None, **options: Any) -> Any:
    """The papers' settings (``<name>-default``): the class's defaults, ``options`` over them."""
    return cls(**{"name": name, "description": description, **options})


def _tuned_adaptive(cls: type, description: str, scenario: Scenario | None = None, *,
                    parameters: str | None = None, **options: Any) -> Any:
    """The tuned settings (``<name>``): the committed sweep result of the scenario's model family
    (:func:`~fkn_bench.training.artifacts.committed_artifact`, written by ``fkn-bench sweep
    --write-artifact``) or ``parameters=PATH``, ``options`` over them."""
    path = parameters if parameters is not None else committed_artifact(cls.name, scenario, swept=True)
    document = read_artifact(path)
    if document["estimator"] != cls.name:
        raise ArtifactError(f"{path} holds {document['estimator']!r} settings, not {cls.name}'s")
    tuned = {k: v for k, v in document["estimator_config"].items() if k not in ("name", "description")}
    if {"adapt_q", "adapt_r"} & set(options):  # the caller's choice of what to adapt replaces the tuned one
        tuned.pop("adapt", None)
    if "adapt" in options:
        tuned = {k: v for k, v in tuned.items() if k not in ("adapt_q", "adapt_r")}
    source = f"tuned on {document.get('scenario', {}).get('name', document['family'])}"
    try:
        cls(**tuned)  # the file's settings alone: a value of the wrong kind is the file's error, named so
    except (TypeError, ValueError) as exc:
        raise ArtifactError(f"{path}: invalid {cls.name} settings: {exc}") from None
    return cls(**{"description": f"{description} ({source})", **tuned, **options})


# The papers' settings stay registered as <name>-default; <name> runs the settings a sweep with
# FlexKalmanNet's budget and objective found (fkn_bench/sweep/spaces/<name>.toml; issue 21).
for _cls, _description, _tuned in (
    (SageHusaEstimator, "Sage-Husa adaptive EKF: forgetting factor 0.99, R by innovation covariance matching, eigenvalue clamping",
     "Sage-Husa adaptive EKF, hyperparameters and initial noise swept"),
    (AkhlaghiEstimator, "Adaptive EKF of Akhlaghi, Zhou & Huang 2017: alpha 0.3, residual-based R, innovation-based Q",
     "Adaptive EKF of Akhlaghi, Zhou & Huang 2017, hyperparameters and initial noise swept"),
    (VBAKFEstimator, "Variational Bayesian adaptive EKF of Huang et al. 2018 (TAC 63(2)): inverse-Wishart P- and R, 10 iterations",
     "Variational Bayesian adaptive EKF of Huang et al. 2018, hyperparameters and initial noise swept"),
):
    register_estimator(_cls.name, partial(_tuned_adaptive, _cls, _tuned), description=_tuned, params_package=PARAMS_PACKAGE)
    register_estimator(f"{_cls.name}-default", partial(_adaptive, _cls, f"{_cls.name}-default", f"{_description} (the paper's settings)"),
                       description=f"{_description} (the paper's settings)")
for _name in TUNED_OBJECTIVES:
    register_estimator(
        _name,
        artifact_factory(_name, TunedEKFEstimator),
        description=DESCRIPTIONS[_name],
        trainable=tuned_trainable(_name),
        params_package=PARAMS_PACKAGE,
    )
