"""The objective of a sweep trial: train with the trial's hyperparameters, return the validation
13-state RMSE.

A trial trains the task's estimator in process with :func:`fkn_bench.training.fit` (no files):
its options are the space's ``[fixed]`` values and the trial's, read by the estimator's
:class:`~fkn_bench.training.Trainable` declaration. After every epoch the ``on_epoch`` callback
reports the validation RMSE (``trial.report(val_rmse, epoch)``) and raises
:class:`optuna.TrialPruned` when the study's pruner says so, whatever the estimator. The trial's
value is the validation RMSE at its best epoch (for the ``nll`` objective the best epoch is
chosen by the NLL, and the RMSE is still what the sweep compares, so trials with different
objectives rank on one scale).

A configuration that the estimator refuses (e.g. ``loss_cut >= window``) or a training that
diverges (non-finite loss) fails the trial with the message as its ``error`` attribute; the sweep
goes on.

An estimator that is not trainable (the adaptive baselines: Sage-Husa, Akhlaghi, VBAKF) is swept
over its options (its factory's keywords: forgetting factors, windows, iteration counts, the
initial noise scales): a trial builds it with the trial's options and runs it over the same
validation data, with the same loss cut, as FlexKalmanNet's training validates on (the val split
of the scenario's data set, :func:`fkn_bench.training.data.training_data` with FlexKalmanNet's
default data protocol), and its value is that validation 13-state RMSE: the same objective and,
with the same trial counts, the same tuning budget as the learned filters.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import optuna

from fkn_bench.scenarios import Scenario
from fkn_bench.sweep.space import SearchSpace

__all__ = ["TrialError", "SweepTask", "EstimatorOptions", "is_trainable", "make_objective", "trial_config", "CATCH"]


class TrialError(Exception):
    """A trial that cannot run (invalid configuration) or failed (diverged training)."""


CATCH: tuple[type[BaseException], ...] = (TrialError,)
"""Exceptions that fail one trial without stopping the sweep."""


@dataclass(frozen=True)
class SweepTask:
    """What every worker needs to evaluate trials (picklable: sent to worker processes): the
    estimator, the training scenario (its train and val splits) and the search space."""

    estimator: str
    scenario: Scenario
    space: SearchSpace


@dataclass(frozen=True)
class EstimatorOptions:
    """The configuration a sweep of a non-trainable estimator searches: its factory's options
    (``to_dict()`` is what ``best.toml`` holds, for ``--estimator-option KEY=VALUE``)."""

    estimator: str
    options: Mapping[str, Any]

    def to_dict(self) -> dict[str, Any]:
        return dict(self.options)

    def build(self, scenario: Scenario | None = None) -> Any:
        """The estimator with these options (ValueError or TypeError when it refuses them)."""
        from fkn_bench.estimators import make_estimator

        return make_estimator(self.estimator, scenario=scenario, **self.options)


def is_trainable(estimator: str) -> bool:
    """Whether ``estimator`` declares a training (else a sweep searches its options)."""
    from fkn_bench.estimators.registry import estimator_spec

    return estimator_spec(estimator).trainable is not None


def trial_config(estimator: str, space: SearchSpace, params: Mapping[str, Any]) -> Any:
    """The configuration of ``estimator`` for a trial: its defaults, then ``[fixed]``, then the
    trial's ``params`` (raises ``ValueError`` or ``TypeError`` when invalid): a training config,
    or for a non-trainable estimator its :class:`EstimatorOptions` (checked by building it)."""
    if not is_trainable(estimator):
        config = EstimatorOptions(estimator, {**space.fixed, **params})
        config.build()
        return config
    from fkn_bench.training import trainable

    return trainable(estimator).config({**space.fixed, **params})


def _validation_data(scenario: Scenario) -> Any:
    """The validation sequences FlexKalmanNet's training validates on, and its loss cut."""
    from fkn_bench.training import trainable
    from fkn_bench.training.data import training_data

    settings = trainable("flexkalmannet").config({}).train_config()
    return training_data(scenario, settings).val, int(settings.loss_cut)


def _evaluation_objective(task: SweepTask) -> Callable[[optuna.Trial], float]:
    """A non-trainable estimator's objective (module docstring): one evaluation per trial."""
    import numpy as np
    import torch

    from fkn_bench.training.objectives import state_mse

    val, loss_cut = _validation_data(task.scenario)
    measurements, mask = val.measurements.numpy(), val.mask.numpy()

    def objective(trial: optuna.Trial) -> float:
        trial.set_user_attr("process", os.getpid())
        params = task.space.suggest(trial)
        began = time.perf_counter()
        try:
            estimator = trial_config(task.estimator, task.space, params).build(task.scenario)
        except (ValueError, TypeError) as exc:
            trial.set_user_attr("error", f"invalid configuration: {exc}")
            raise TrialError(f"trial {trial.number}: invalid configuration: {exc}") from None
        means = estimator.estimate(np.array(measurements), np.array(mask), float(task.scenario.dt)).means
        try:
            rmse = math.sqrt(float(state_mse(torch.from_numpy(np.ascontiguousarray(means)), val.truth, loss_cut)))
        except ValueError as exc:  # e.g. a validation split no longer than the loss cut
            trial.set_user_attr("error", str(exc))
            raise TrialError(f"trial {trial.number}: {exc}") from None
        if not math.isfinite(rmse):
            trial.set_user_attr("error", "non-finite validation RMSE")
            raise TrialError(f"trial {trial.number}: non-finite validation RMSE")
        trial.set_user_attr("seconds", time.perf_counter() - began)
        trial.report(rmse, 1)
        return rmse

    return objective


def _value(val_rmse: float, val_loss: float) -> float:
    """The validation RMSE of an epoch (the validation loss where no RMSE is logged)."""
    return val_rmse if math.isfinite(val_rmse) else val_loss


def make_objective(task: SweepTask) -> Callable[[optuna.Trial], float]:
    """The objective of ``task`` (module docstring)."""
    from fkn_bench.training import fit

    if not is_trainable(task.estimator):
        return _evaluation_objective(task)

    def objective(trial: optuna.Trial) -> float:
        trial.set_user_attr("process", os.getpid())
        params = task.space.suggest(trial)
        try:
            config = trial_config(task.estimator, task.space, params)
        except (ValueError, TypeError) as exc:
            trial.set_user_attr("error", f"invalid configuration: {exc}")
            raise TrialError(f"trial {trial.number}: invalid configuration: {exc}") from None
        began = time.perf_counter()

        def on_epoch(epoch: int, history: list[Any]) -> None:
            value = _value(history[-1].val_rmse, history[-1].val_loss)
            trial.report(float(value), epoch)
            if trial.should_prune():
                trial.set_user_attr("epochs_run", epoch)
                trial.set_user_attr("seconds", time.perf_counter() - began)
                raise optuna.TrialPruned(f"pruned after epoch {epoch} (validation RMSE {value:.5g})")

        try:
            outcome = fit(task.estimator, task.scenario, config, progress=False, on_epoch=on_epoch)
        except (ValueError, TypeError, FloatingPointError) as exc:
            trial.set_user_attr("error", str(exc))
            raise TrialError(f"trial {trial.number}: {exc}") from None
        best = outcome.best()
        if not best:
            raise TrialError(f"trial {trial.number}: no epoch completed")
        seconds, epochs = time.perf_counter() - began, len(outcome.history)
        for key, value in {"best_epoch": int(outcome.best_epoch), "epochs_run": epochs, "seconds": seconds,
                           "seconds_per_epoch": seconds / max(epochs, 1)}.items():
            trial.set_user_attr(key, value)
        for key in ("gradient_steps_taken", "gradient_steps_clipped", "gradient_steps_skipped_nonfinite",
                    "gradient_steps_rolled_back"):
            if key in outcome.history:  # recurrent networks: clipping engaged, non-finite steps skipped or undone
                trial.set_user_attr(key, int(outcome.history[key].iloc[-1]))  # cumulative counts
        if outcome.config.train_config().objective != "supervised":
            trial.set_user_attr("best_val_loss", float(outcome.best_loss))
        return float(_value(best["val_rmse"], best["val_loss"]))

    return objective
