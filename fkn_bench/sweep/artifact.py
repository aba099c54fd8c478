"""A sweep's best options as the committed settings of a non-trainable estimator
(``fkn-bench sweep --write-artifact``): the adaptive baselines' tuned settings.

A sweep of ``<name>-default`` (the method with its paper's settings, which the trials' options
override) installs the tuned settings of ``<name>``; a sweep of any other non-trainable estimator
installs its own. The file is a learned-parameter artefact (:mod:`fkn_bench.training.artifacts`)
``<name>-<family>.json`` in the ``params/`` folder of the package that ``<name>``'s registration
names (``params_package``; ``baselines/params`` for the adaptive baselines): ``estimator_config``
holds the options (the estimator's factory keywords), ``training`` how they were found (the
search space and its fingerprint, the sampler, the trial counts, the best validation RMSE and
trial), ``provenance`` the run's versions, commit and command line.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fkn_bench.sweep.objective import trial_config

__all__ = ["install_sweep_options", "tuned_name"]


def tuned_name(estimator: str) -> str:
    """The estimator whose settings a sweep of ``estimator`` installs (see module docstring)."""
    return estimator.removesuffix("-default")


def install_sweep_options(settings: Any, result: Any) -> Path:
    """Write the best options of the sweep ``settings`` (``result``: its
    :class:`~fkn_bench.sweep.runner.SweepResult`) as ``settings.estimator``'s committed settings
    for the scenario's model family; returns the file (written atomically)."""
    from fkn_bench.training.artifacts import artifact_path, write_artifact

    scenario = settings.scenario
    options = trial_config(settings.estimator, settings.space, result.best_params).to_dict()
    target = tuned_name(settings.estimator)
    return write_artifact(
        artifact_path(target, scenario.model_family),
        estimator=target,
        family=scenario.model_family,
        scenario={"name": scenario.name, "config_hash": scenario.config_hash()},
        estimator_config=options,
        parameters={},
        training={
            "method": f"fkn-bench sweep of {settings.estimator}'s options (no training)",
            "objective": "validation 13-state RMSE (FlexKalmanNet's validation split and loss cut)",
            "best_value": result.best_value,
            "best_trial": {"stage": result.best_stage, "number": result.best_number},
            "trials": result.counts,
            "sampler": settings.sampler,
            "space": settings.space.to_dict(),
            "space_fingerprint": settings.space.fingerprint(),
        },
    )
