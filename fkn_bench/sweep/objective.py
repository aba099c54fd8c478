"""The objective of a sweep trial: train with the trial's hyperparameters, return the validation
13-state RMSE.

FlexKalmanNet trials train in process with the shared :class:`~fkn_bench.training.Trainer` (no
checkpoints or figures): after every epoch the ``on_epoch`` callback reports the validation RMSE
(``trial.report(val_rmse, epoch)``) and raises :class:`optuna.TrialPruned` when the study's pruner
says so. The trial's value is the validation RMSE at its best epoch (for the ``nll`` objective the
best epoch is chosen by the NLL, and the RMSE is still what the sweep compares, so trials with
different objectives rank on one scale).

Any other trainable estimator (``fkn-bench train --estimator NAME``) is trained with its
registered train function into ``OUT/trials/<number>``; its epochs are reported from the
``history.csv`` it writes after training, so such trials are not pruned.

A configuration that the estimator refuses (e.g. ``loss_cut >= window``) or a training that
diverges (non-finite loss) fails the trial with the message as its ``error`` attribute; the sweep
goes on.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import optuna

from fkn_bench.scenarios import Scenario
from fkn_bench.sweep.space import SearchSpace

__all__ = ["TrialError", "SweepTask", "make_objective", "coerce_config", "trial_config", "CATCH"]


class TrialError(Exception):
    """A trial that cannot run (invalid configuration) or failed (diverged training)."""


CATCH: tuple[type[BaseException], ...] = (TrialError,)
"""Exceptions that fail one trial without stopping the sweep."""


@dataclass(frozen=True)
class SweepTask:
    """What every worker needs to evaluate trials (picklable: sent to worker processes).

    Attributes:
        estimator: trainable estimator name.
        scenario: training scenario (its train and val splits are used).
        space: the search space.
        out: sweep output directory (trial directories of non-FlexKalmanNet estimators).
    """

    estimator: str
    scenario: Scenario
    space: SearchSpace
    out: Path


def coerce_config(values: Mapping[str, Any], defaults: Mapping[str, Any]) -> dict[str, Any]:
    """Turn comma-separated strings into tuples for tuple-valued fields (``learn``)."""
    out = dict(values)
    for key, value in values.items():
        if isinstance(defaults.get(key), (tuple, list)) and isinstance(value, str):
            out[key] = tuple(part.strip() for part in value.split(",") if part.strip())
    return out


def trial_config(space: SearchSpace, params: Mapping[str, Any]) -> Any:
    """The :class:`~fkn_bench.flexkalmannet.FlexKalmanNetConfig` of a trial: the defaults, then
    ``[fixed]``, then the trial's ``params`` (raises ``ValueError`` when invalid)."""
    from fkn_bench.flexkalmannet import FlexKalmanNetConfig

    base = FlexKalmanNetConfig()
    defaults = {f.name: getattr(base, f.name) for f in dataclasses.fields(base)}
    return base.replace(**coerce_config({**space.fixed, **params}, defaults))


@lru_cache(maxsize=4)
def _training_data(scenario: Scenario, window: int, stride: int | None, every: int | None, episodes: int) -> Any:
    from fkn_bench.training import TrainingData

    return TrainingData(scenario, window=window, stride=stride, train_measurement_every=every, episodes=episodes)


def _flexkalmannet_objective(task: SweepTask) -> Callable[[optuna.Trial], float]:
    import torch

    from fkn_bench.filters import make_filter
    from fkn_bench.flexkalmannet.checkpoint import build_model
    from fkn_bench.training import Trainer

    def objective(trial: optuna.Trial) -> float:
        params = task.space.suggest(trial)
        try:
            config = trial_config(task.space, params)
            data = _training_data(task.scenario, config.window, config.stride, config.train_measurement_every, config.episodes)
            model = build_model(config, data)
            trainer = Trainer(model, make_filter(config.variant), data, config.train_config())
        except (ValueError, TypeError) as exc:
            trial.set_user_attr("error", f"invalid configuration: {exc}")
            raise TrialError(f"trial {trial.number}: invalid configuration: {exc}") from None
        began = time.perf_counter()

        def on_epoch(trainer: Trainer, record: Any) -> None:
            value = record.val_rmse if math.isfinite(record.val_rmse) else record.val_loss
            trial.report(float(value), record.epoch)
            if trial.should_prune():
                trial.set_user_attr("epochs_run", record.epoch)
                trial.set_user_attr("seconds", time.perf_counter() - began)
                raise optuna.TrialPruned(f"pruned after epoch {record.epoch} (validation RMSE {value:.5g})")

        torch.manual_seed(config.seed)
        try:
            trainer.fit(on_epoch=on_epoch, progress=False)
        except FloatingPointError as exc:
            trial.set_user_attr("error", str(exc))
            raise TrialError(f"trial {trial.number}: {exc}") from None
        best = next((r for r in trainer.history if r.epoch == trainer.best_epoch), None)
        if best is None:
            raise TrialError(f"trial {trial.number}: no epoch completed")
        value = best.val_rmse if math.isfinite(best.val_rmse) else best.val_loss
        seconds = time.perf_counter() - began
        trial.set_user_attr("best_epoch", int(trainer.best_epoch))
        trial.set_user_attr("epochs_run", len(trainer.history))
        trial.set_user_attr("seconds", seconds)
        trial.set_user_attr("seconds_per_epoch", seconds / max(len(trainer.history), 1))
        if config.objective != "supervised":
            trial.set_user_attr("best_val_loss", float(trainer.best_loss))
        return float(value)

    return objective


def _generic_objective(task: SweepTask) -> Callable[[optuna.Trial], float]:
    import pandas as pd

    from fkn_bench.estimators import estimator_spec

    spec = estimator_spec(task.estimator)
    if spec.train is None:
        raise ValueError(f"estimator {task.estimator!r} is not trainable")
    train = spec.train

    def objective(trial: optuna.Trial) -> float:
        params = task.space.suggest(trial)
        out = task.out / "trials" / f"{trial.number:05d}"
        began = time.perf_counter()
        try:
            summary = train(task.scenario, out=out, options={**task.space.fixed, **params}, resume=False, progress=False)
        except (ValueError, TypeError, FloatingPointError) as exc:
            trial.set_user_attr("error", str(exc))
            raise TrialError(f"trial {trial.number}: {exc}") from None
        history_path = out / "history.csv"
        values: dict[int, float] = {}
        if history_path.is_file():
            history = pd.read_csv(history_path)
            column = "val_rmse" if "val_rmse" in history.columns else "val_loss"
            values = {int(e): float(v) for e, v in zip(history["epoch"], history[column])}
            for epoch, value in values.items():
                if math.isfinite(value):
                    trial.report(value, epoch)
        best_epoch = int(summary.get("best_epoch") or 0)
        value = values.get(best_epoch, summary.get("best_val_loss", math.nan))
        if value is None or not math.isfinite(float(value)):
            raise TrialError(f"trial {trial.number}: no validation loss in {history_path} or the training summary")
        trial.set_user_attr("best_epoch", best_epoch)
        trial.set_user_attr("epochs_run", len(values))
        trial.set_user_attr("seconds", time.perf_counter() - began)
        return float(value)

    return objective


def make_objective(task: SweepTask) -> Callable[[optuna.Trial], float]:
    """The objective of ``task.estimator`` (module docstring)."""
    if task.estimator == "flexkalmannet":
        return _flexkalmannet_objective(task)
    return _generic_objective(task)
