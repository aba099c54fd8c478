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

__all__ = ["TrialError", "SweepTask", "make_objective", "trial_config", "CATCH"]


class TrialError(Exception):
    """A trial that cannot run (invalid configuration) or failed (diverged training)."""


CATCH: tuple[type[BaseException], ...] = (TrialError,)
"""Exceptions that fail one trial without stopping the sweep."""


@dataclass(frozen=True)
class SweepTask:
    """What every worker needs to evaluate trials (picklable: sent to worker processes): the
    trainable estimator, the training scenario (its train and val splits) and the search space."""

    estimator: str
    scenario: Scenario
    space: SearchSpace


def trial_config(estimator: str, space: SearchSpace, params: Mapping[str, Any]) -> Any:
    """The training config of ``estimator`` for a trial: its defaults, then ``[fixed]``, then the
    trial's ``params`` (raises ``ValueError`` or ``TypeError`` when invalid)."""
    from fkn_bench.training import trainable

    return trainable(estimator).config({**space.fixed, **params})


def _value(val_rmse: float, val_loss: float) -> float:
    """The validation RMSE of an epoch (the validation loss where no RMSE is logged)."""
    return val_rmse if math.isfinite(val_rmse) else val_loss


def make_objective(task: SweepTask) -> Callable[[optuna.Trial], float]:
    """The objective of ``task`` (module docstring)."""
    from fkn_bench.training import fit, trainable

    trainable(task.estimator)  # raises ValueError when it is not trainable

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
