"""The one training pipeline: :func:`fit` trains any registered trainable estimator.

An estimator is trainable when its registry entry declares a :class:`Trainable` (how to read its
training config from options, and how to build the module whose parameters are trained);
``fit`` does the rest for all of them (FlexKalmanNet, the tuned EKFs, ``fkn-bench train``,
``fkn-bench sweep``): data, objective, optimiser, early stopping, checkpoint and resume,
per-epoch history, an ``on_epoch`` callback, and with ``out=DIR`` these files:

* ``checkpoint.pt``: everything to resume (``resume=True``; see
  :mod:`fkn_bench.training.checkpoint`), written atomically after the first epoch, then after an
  epoch when :data:`CHECKPOINT_INTERVAL_S` have passed since the last one, and at the end. A run
  killed at any point (or stopped by a full disk) and resumed gives exactly the numbers of the
  uninterrupted run: the checkpoint holds every random generator's state;
* ``history.csv``: epoch, losses, validation RMSE, learning rate, seconds and the deployed
  standard deviations;
* ``loss.png`` and ``parameters.png``: the loss curves and the learned standard deviations over
  epochs (FlexKalmanNet's Fig. 3 and 4);
* ``parameters.json``: the learned-parameter artefact of the best epoch (the format of the
  committed ``<package>/params/<estimator>-<family>.json``, see
  :mod:`fkn_bench.training.artifacts`), with the test-split metrics and the per-epoch history
  (``training.history``: every column of ``history.csv`` but the seconds), so that a committed
  artefact can be checked against a short retraining.

Every file is written atomically (:mod:`fkn_bench.io`): a write that fails, e.g. on a full disk,
raises :class:`~fkn_bench.io.WriteError` (:class:`~fkn_bench.io.DiskFullError`) naming the file
and leaves the file it would have replaced as it was, so ``resume=True`` continues from the last
complete checkpoint. ``out`` is locked while a run writes into it (a second run into it is refused
with :class:`~fkn_bench.io.LockedError`), and the temporary files of a killed run are removed.

A trainable whose module is a :class:`~fkn_bench.training.trainer.SequenceModel` (KalmanNet: a
network inside the filter loop, no noise parameters) gets the same files but ``parameters.png``;
its ``parameters.json`` holds the module's description, its ``estimator_config`` names the
checkpoint (the weights), and ``history.csv`` the gradient steps taken, clipped and skipped. A
:class:`~fkn_bench.training.trainer.NoiseModel` that deploys its network (FlexKalmanNet's
time-varying mode, ``flexkalmannet-tv``) also names the checkpoint, and is scored on the test
split with its per-step parameters.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import torch

from fkn_bench.io import atomic_path, directory_lock, read_toml, remove_temporaries
from fkn_bench.models.registry import model_spec
from fkn_bench.runtime import torch_threads
from fkn_bench.scenarios import Scenario, get_scenario
from fkn_bench.training.artifacts import deployed_estimator_config, run_provenance, write_artifact
from fkn_bench.training.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from fkn_bench.training.data import TrainingData, training_data
from fkn_bench.training.objectives import OBJECTIVE_LABELS, aligned_state_error, state_mse
from fkn_bench.training.options import FileOptions
from fkn_bench.training.trainer import NoiseModel, OnEpoch, SequenceModel, TrainConfig, Trainer

__all__ = ["CHECKPOINT_INTERVAL_S", "Trainable", "TrainingOutcome", "fit", "options_with_file", "split_metrics", "trainable"]


@dataclass(frozen=True)
class Trainable:
    """The declaration that makes a registered estimator trainable
    (``register_estimator(name, factory, trainable=Trainable(...))``).

    Attributes:
        config: ``options -> config``: the estimator's training configuration from option values
            (``fkn-bench train --set``/``--epochs``..., a sweep trial's values); raises ValueError
            or TypeError for invalid ones. The config has ``to_dict()`` (stored in checkpoints and
            artefacts; its keys are the options a sweep may search) and
            ``train_config() -> TrainConfig`` (data protocol, filter variant, objective,
            optimiser). ``config({})`` is the default configuration.
        build: ``(config, data) -> NoiseModel | SequenceModel``: the module whose parameters are
            trained, initialised (seeded by the config); a
            :class:`~fkn_bench.training.trainer.SequenceModel` brings its own recursion.
        notes: extra entries of the artefact's ``training`` record.
    """

    config: Callable[[Mapping[str, Any]], Any]
    build: Callable[[Any, TrainingData], NoiseModel | SequenceModel]
    notes: Mapping[str, Any] = field(default_factory=dict)

CHECKPOINT_INTERVAL_S = 10.0
"""Seconds of training between checkpoints (after the first epoch, which is always saved, and
besides the one at the end): an interrupted run loses at most this much. A checkpoint holds the
network, the best weights, the optimiser's state and the weights (and optimiser state) before the
epoch's last step, so that a resumed run can undo that step as the uninterrupted one would; it is
written and fsynced, so writing one per epoch would cost a noticeable share of a run whose epochs
last about a second (sizes and costs: ``fkn_bench/DESIGN.md``, "Performance notes")."""


def trainable(estimator: str) -> Trainable:
    """The :class:`Trainable` of the registered ``estimator`` (ValueError when it has none)."""
    from fkn_bench.estimators.registry import estimator_spec, estimator_specs

    declared = estimator_spec(estimator).trainable
    if declared is None:
        names = ", ".join(s.name for s in estimator_specs() if s.trainable)
        raise ValueError(f"estimator {estimator!r} is not trainable; trainable estimators: {names}")
    return declared


def _artifact_config(path: str | Path) -> dict[str, Any]:
    """The training configuration a learned-parameter artefact (``.json``) records, without its
    seed and the values it left unset: what retrains it (``--config ARTEFACT --seed K``, or a seed
    study's ``--seeds``)."""
    from fkn_bench.training.artifacts import read_artifact

    config = (read_artifact(path).get("training") or {}).get("config")
    if not isinstance(config, dict):
        raise ValueError(f"{path}: a learned-parameter file without a training configuration ('training.config')")
    return {k: v for k, v in config.items() if v is not None and k != "seed"}


def options_with_file(options: Mapping[str, Any], *tables: str) -> dict[str, Any]:
    """``options`` over the values of the TOML file named by option ``config`` (its first table
    of ``tables`` that exists, else its top level), or of the training configuration of the
    learned-parameter artefact it names (a ``.json`` file: a committed ``params/<estimator>-<family>.json``
    retrains with the configuration it was trained with), as
    :class:`~fkn_bench.training.options.FileOptions` that remember which keys the file gave
    (errors name it); ``options`` without ``config`` as they are."""
    options = dict(options)
    path = options.pop("config", None)
    if not path:
        return options
    if str(path).endswith(".json"):
        table = _artifact_config(path)
        return FileOptions({**table, **options}, {key: str(path) for key in table if key not in options})
    document = read_toml(path)
    table = next((document[t] for t in tables if t in document), document)
    if not isinstance(table, dict):
        raise ValueError(f"{path}: [{next(t for t in tables if t in document)}] must be a table of configuration values")
    return FileOptions({**table, **options}, {key: str(path) for key in table if key not in options})


@dataclass
class TrainingOutcome:
    """What a training run produced (``out`` is None for a run without files, e.g. a sweep trial)."""

    estimator: str
    model: NoiseModel | SequenceModel
    config: Any
    scenario: Scenario
    history: pd.DataFrame
    best_epoch: int
    best_loss: float
    out: Path | None
    test: dict[str, Any]
    seconds: float
    estimator_config: dict[str, Any]
    scenarios: tuple[Scenario, ...] = ()
    family: str = ""

    @property
    def checkpoint(self) -> Path:
        return Path(self.out or ".") / "checkpoint.pt"

    @property
    def artifact(self) -> Path:
        return Path(self.out or ".") / "parameters.json"

    def best(self) -> dict[str, float]:
        """The history row of the best epoch (empty before any epoch)."""
        rows = self.history[self.history["epoch"] == self.best_epoch] if len(self.history) else self.history
        return {str(k): float(v) for k, v in rows.iloc[0].items()} if len(rows) else {}

    def summary(self) -> dict[str, Any]:
        """What ``fkn-bench train`` reports."""
        return {
            "estimator": self.estimator,
            "scenario": "+".join(s.name for s in self.scenarios) or self.scenario.name,
            "family": self.family or self.scenario.model_family,
            "out": str(self.out),
            "checkpoint": str(self.checkpoint),
            "artifact": str(self.artifact),
            "epochs_run": len(self.history),
            "best_epoch": self.best_epoch,
            "seconds": self.seconds,
            **{k: self.estimator_config[k] for k in ("q_std", "r_std") if k in self.estimator_config},
            **self.test,
        }


def _deployed(model: NoiseModel | SequenceModel) -> dict[str, Any]:
    """What the trained module deploys, JSON-compatible: the learned parameters, or a
    :class:`SequenceModel`'s own description."""
    if isinstance(model, SequenceModel):
        return model.describe()
    with torch.no_grad():
        return model.parameter_set.to_dict(model.deployed_raw())


def split_metrics(model: NoiseModel | SequenceModel, settings: TrainConfig, scenario: Scenario) -> dict[str, Any]:
    """13-state RMSE (FlexKalmanNet's test loss) and per-component RMSE of the deployed
    parameters on the test split of the data set, scored after the loss cut, with the scenario's
    measurement schedule."""
    from fkn_bench.envs import generate_episodes
    from fkn_bench.types import STATE_NAMES

    episode = generate_episodes(scenario, [scenario.dataset_seed], split="test")
    cut = settings.loss_cut
    device = next(iter(model.parameters()), torch.empty(0)).device  # (where it was trained)
    with torch.no_grad(), torch_threads(settings.threads):
        z, mask = torch.as_tensor(episode.measurements, device=device), torch.as_tensor(episode.valid, device=device)
        if isinstance(model, SequenceModel):
            means = model.run_means(z, mask, dt=scenario.dt)
        else:
            noise = model.parameter_set.to_noise(model.sequence_raw(z, mask))
            means = settings.build_filter(scenario).run(noise, z, mask, dt=scenario.dt, store_covariances=False,
                                                        store_innovations=False).means
        truth = torch.as_tensor(episode.truth, device=device)
        mse = float(state_mse(means, truth, cut))
        per_component = aligned_state_error(means[:, cut:], truth[:, cut:]).square().mean((0, 1)).sqrt().cpu().numpy()
    return {
        "test_rmse": math.sqrt(mse),
        "test_rmse_components": dict(zip(STATE_NAMES, np.round(per_component, 8).tolist())),
        "test_seed": scenario.dataset_seed,
        "loss_cut": cut,
    }


def fit(
    estimator: str,
    scenario: str | Scenario | Sequence[str | Scenario] = "ds1",
    config: Any = None,
    *,
    out: str | Path | None = None,
    resume: bool = False,
    progress: bool = True,
    plots: bool = True,
    on_epoch: OnEpoch | None = None,
    family: str | None = None,
) -> TrainingOutcome:
    """Train the registered trainable ``estimator`` on ``scenario``'s data set (module docstring).

    Args:
        estimator: registry name of a trainable estimator.
        scenario: training scenario (name or object); its train and val splits are used, the
            test split scores the result. A sequence of scenarios trains on their mixture (see
            :class:`~fkn_bench.training.TrainingData`; the test metrics are the mean over them).
        config: the estimator's training config, or options for its :attr:`Trainable.config`
            (None: the defaults).
        out: output directory (created), locked for the run (:func:`fkn_bench.io.directory_lock`:
            a second training into it is refused with :class:`~fkn_bench.io.LockedError`), its
            stray temporary files removed; None: no files, no test metrics.
        resume: continue from ``out/checkpoint.pt`` (same estimator, config and scenario), exactly
            where the uninterrupted run would be (:meth:`~fkn_bench.training.Trainer.state_dict`).
        progress: show a progress bar on stderr.
        plots: write the two training figures.
        on_epoch: ``on_epoch(epoch, history)`` after every epoch (and its checkpoint, when one
            is due); see :data:`~fkn_bench.training.trainer.OnEpoch`.
        family: the model family the artefact is for (default: the scenarios' common
            ``model_family``, else ``default``).
    """
    if out is None:
        return _fit(estimator, scenario, config, None, resume, progress, plots, on_epoch, family)
    with directory_lock(out, "a training run"):
        remove_temporaries(out, recursive=False)  # (what a killed run's atomic writes left)
        return _fit(estimator, scenario, config, Path(out), resume, progress, plots, on_epoch, family)


def _fit(estimator: str, scenario: str | Scenario | Sequence[str | Scenario], config: Any, directory: Path | None,
         resume: bool, progress: bool, plots: bool, on_epoch: OnEpoch | None, family: str | None) -> TrainingOutcome:
    """:func:`fit` (into ``directory``, whose lock the caller holds, or without files)."""
    declared = trainable(estimator)
    scenarios = [get_scenario(s) for s in ([scenario] if isinstance(scenario, (str, Scenario)) else scenario)]
    scenario = scenarios[0]
    label = "+".join(s.name for s in scenarios)
    if family is None:
        family = scenario.model_family if len({s.model_family for s in scenarios}) == 1 else "default"
    config = declared.config(config or {}) if config is None or isinstance(config, Mapping) else config
    if model_spec(config.train_config().process_model).inertia == "required" and config.train_config().inertia is None:
        config = dataclasses.replace(config, inertia=scenario.inertia)  # deployed with the inertia trained on
    settings: TrainConfig = config.train_config()
    began = time.perf_counter()
    data = training_data(scenario if len(scenarios) == 1 else scenarios, settings)
    model = declared.build(config, data)
    trainer = Trainer(model, settings.build_filter(scenario), data, settings)
    checkpoint = None if directory is None else directory / "checkpoint.pt"
    torch.manual_seed(settings.seed)  # (dropout's generator; a resumed trainer restores its state)
    if resume:
        if checkpoint is None:
            raise ValueError("resume=True needs out=DIR (the directory of the checkpoint to resume)")
        document = load_checkpoint(checkpoint)
        if document["estimator"] != estimator or document["config"] != config.to_dict():
            raise CheckpointError(f"cannot resume {checkpoint}: it was trained with another estimator or a different config")
        if document["scenario"] != _scenario_record(scenarios):
            raise CheckpointError(f"cannot resume {checkpoint}: it was trained on a different scenario")
        trainer.load_state_dict(document["trainer"])

    def save() -> None:
        if checkpoint is not None:
            save_checkpoint(checkpoint, {
                "estimator": estimator,
                "config": config.to_dict(),
                "scenario": _scenario_record(scenarios),
                "data": data.describe(),
                "state_dict": model.state_dict(),
                "trainer": trainer.state_dict(),
                "deployed": _deployed(model),
                "best_epoch": trainer.best_epoch,
                "provenance": run_provenance(),
            })

    last_saved = -math.inf

    def after_epoch(epoch: int, history: list[Any]) -> bool | None:
        nonlocal last_saved
        if epoch == 1 or time.monotonic() - last_saved >= CHECKPOINT_INTERVAL_S:
            save()
            last_saved = time.monotonic()
        return on_epoch(epoch, history) if on_epoch is not None else None

    earlier = sum(record.seconds for record in trainer.history)  # resumed: the epochs run before
    trainer.fit(on_epoch=after_epoch, progress=progress)  # restores the best epoch's weights
    save()
    history = pd.DataFrame([record.flat() for record in trainer.history])
    outcome = TrainingOutcome(
        estimator, model, config, scenario, history, trainer.best_epoch, trainer.best_loss, directory, {},
        time.perf_counter() - began + earlier,
        {"checkpoint": None if checkpoint is None else str(checkpoint)}
        if isinstance(model, SequenceModel) or model.deploys_network else deployed_estimator_config(model, settings), tuple(scenarios), family,
    )
    if directory is None:
        return outcome
    from fkn_bench.training.plots import plot_losses, plot_parameters

    with atomic_path(directory / "history.csv") as tmp:
        history.to_csv(tmp, index=False)
    if plots and len(history):
        loss = OBJECTIVE_LABELS[settings.objective].removesuffix(" per update").removesuffix(" per step")
        plot_losses(history, directory / "loss.png", title=f"{estimator} on {label} ({loss})",
                    best_epoch=trainer.best_epoch, loss=loss)
        if not isinstance(model, SequenceModel):  # a network's own recursion has no standard deviations
            plot_parameters(history, directory / "parameters.png",
                            title=f"{estimator}: learned standard deviations ({label})")
    outcome.test = _mean_metrics([split_metrics(model, settings, s) for s in scenarios], scenarios)
    outcome.seconds = time.perf_counter() - began + earlier  # a resumed run counts its earlier epochs
    training = {
        "objective": settings.objective,
        "optimizer": settings.optimizer,
        "config": config.to_dict(),
        "data": data.describe(),
        "epochs_run": len(history),
        "best_epoch": outcome.best_epoch,
        "best_val_loss": outcome.best_loss,
        "val_loss_is": OBJECTIVE_LABELS[settings.objective],
        **declared.notes,
        "seconds_total": outcome.seconds,
        "seconds_per_epoch": float(history["seconds"].mean()) if len(history) else None,
        "loss_evaluations": trainer.evaluations if settings.optimizer == "lbfgs" else None,
        "gradient_steps": dict(trainer.gradient_steps),
        "divergence_restarts": trainer.divergence_restarts,  # TrainConfig.restart_on_divergence
        "loss_spikes": trainer.loss_spikes,
        **outcome.test,
        "history": {str(c): history[c].tolist() for c in history.columns if c != "seconds"},
    }
    write_artifact(outcome.artifact, estimator=estimator, family=family,
                   scenario={"name": label, "config_hash": "+".join(s.config_hash() for s in scenarios)},
                   estimator_config=outcome.estimator_config,
                   parameters=_deployed(model), training=training)
    return outcome


def _scenario_record(scenarios: Sequence[Scenario]) -> Any:
    """What a checkpoint stores of its training scenario(s) (one dict, or a list for a mixture)."""
    return scenarios[0].to_dict() if len(scenarios) == 1 else [s.to_dict() for s in scenarios]


def _mean_metrics(metrics: Sequence[dict[str, Any]], scenarios: Sequence[Scenario]) -> dict[str, Any]:
    """One scenario's test metrics, or for a mixture their mean with the per-scenario RMSEs."""
    if len(metrics) == 1:
        return metrics[0]
    names = list(metrics[0]["test_rmse_components"])
    return {
        "test_rmse": float(np.mean([m["test_rmse"] for m in metrics])),
        "test_rmse_components": {k: float(np.mean([m["test_rmse_components"][k] for m in metrics])) for k in names},
        "test_rmse_by_scenario": {s.name: m["test_rmse"] for s, m in zip(scenarios, metrics)},
        "test_seed": metrics[0]["test_seed"],
        "loss_cut": metrics[0]["loss_cut"],
    }
