"""Train FlexKalmanNet end to end: data, model, loop, checkpoints, history, plots, artefact.

``train_flexkalmannet(scenario, config, out=DIR)`` writes into ``DIR``:

* ``checkpoint.pt``: after every epoch (atomically), everything to resume (``resume=True``);
* ``history.csv``: epoch, losses, learning rate, seconds and the deployed standard deviations;
* ``loss.png`` and ``parameters.png``: the paper's two training figures (loss curves; the learned
  standard deviations over epochs);
* ``parameters.json``: the learned-parameter artefact of the best epoch (the format of the
  committed ``baselines/params/flexkalmannet-<family>.json``), with the test metrics and the
  per-epoch history (``training.history``: losses, learning rate and the deployed standard
  deviations after every epoch, without the seconds), so that a committed artefact can be checked
  against a short retraining without rerunning all of it.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import torch

from fkn_bench.filters import make_filter
from fkn_bench.flexkalmannet.checkpoint import build_model, load_checkpoint, save_checkpoint
from fkn_bench.flexkalmannet.config import FlexKalmanNetConfig
from fkn_bench.flexkalmannet.estimator import deployed_estimator_config
from fkn_bench.flexkalmannet.network import FlexKalmanNet
from fkn_bench.flexkalmannet.plots import plot_losses, plot_parameters
from fkn_bench.io import atomic_path
from fkn_bench.runtime import torch_threads
from fkn_bench.scenarios import Scenario, get_scenario
from fkn_bench.training import EpochRecord, Trainer, TrainingData, state_mse
from fkn_bench.training.artifacts import run_provenance, write_artifact

__all__ = ["TrainingOutcome", "train_flexkalmannet", "test_split_rmse"]


@dataclass
class TrainingOutcome:
    """What a training run produced."""

    model: FlexKalmanNet
    config: FlexKalmanNetConfig
    scenario: Scenario
    history: pd.DataFrame
    best_epoch: int
    out: Path
    test: dict[str, Any]
    seconds: float

    @property
    def checkpoint(self) -> Path:
        return self.out / "checkpoint.pt"

    @property
    def artifact(self) -> Path:
        return self.out / "parameters.json"


def test_split_rmse(model: FlexKalmanNet, config: FlexKalmanNetConfig, scenario: Scenario) -> dict[str, Any]:
    """13-state RMSE (the paper's test loss) and per-component RMSE of the deployed parameters
    on the test split of the data set, scored after the loss cut, with the scenario's schedule."""
    from fkn_bench.envs import generate_episodes
    from fkn_bench.training.objectives import aligned_state_error

    episode = generate_episodes(scenario, [scenario.dataset_seed], split="test")
    variant = make_filter(config.variant)
    with torch.no_grad(), torch_threads(config.threads):
        noise = model.parameter_set.to_noise(model.deployed_raw())
        z, mask = torch.as_tensor(episode.measurements), torch.as_tensor(episode.valid)
        result = variant.run(noise, z, mask, dt=scenario.dt, store_covariances=False, store_innovations=False)
        truth = torch.as_tensor(episode.truth)
        mse = float(state_mse(result.means, truth, config.loss_cut))
        error = aligned_state_error(result.means[:, config.loss_cut :], truth[:, config.loss_cut :])
        per_component = error.square().mean((0, 1)).sqrt().numpy()
    from fkn_bench.types import STATE_NAMES

    return {
        "test_rmse": math.sqrt(mse),
        "test_rmse_components": dict(zip(STATE_NAMES, np.round(per_component, 8).tolist())),
        "test_seed": scenario.dataset_seed,
        "loss_cut": config.loss_cut,
    }


def _history_frame(history: list[EpochRecord]) -> pd.DataFrame:
    return pd.DataFrame([record.flat() for record in history])


def history_for_artifact(history: pd.DataFrame) -> dict[str, list[float]]:
    """The per-epoch history as ``{column: [value per epoch]}`` for the artefact: every column of
    ``history.csv`` but the wall-clock ``seconds`` (not reproducible)."""
    return {str(c): history[c].tolist() for c in history.columns if c != "seconds"}


def train_flexkalmannet(
    scenario: str | Scenario = "ds1",
    config: FlexKalmanNetConfig | None = None,
    *,
    out: str | Path,
    resume: bool = False,
    progress: bool = True,
    plots: bool = True,
) -> TrainingOutcome:
    """Train FlexKalmanNet on ``scenario``'s data set (see module docstring).

    Args:
        scenario: training scenario (name or object); its train/val splits are used.
        config: :class:`FlexKalmanNetConfig` (default: the project's defaults).
        out: output directory (created).
        resume: continue from ``out/checkpoint.pt`` (its config must match ``config``).
        progress: show a progress bar on stderr.
        plots: write the two training figures.
    """
    scenario = get_scenario(scenario)
    config = config if config is not None else FlexKalmanNetConfig()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    checkpoint_path = out / "checkpoint.pt"
    began = time.perf_counter()

    data = TrainingData(
        scenario,
        window=config.window,
        stride=config.stride,
        train_measurement_every=config.train_measurement_every,
        episodes=config.episodes,
    )
    model = build_model(config, data)
    variant = make_filter(config.variant)
    trainer = Trainer(model, variant, data, config.train_config())
    if resume:
        document = load_checkpoint(checkpoint_path)
        if document["config"] != config.to_dict():
            raise ValueError(f"cannot resume {checkpoint_path}: it was trained with a different config")
        if document["scenario"] != scenario.to_dict():
            raise ValueError(f"cannot resume {checkpoint_path}: it was trained on a different scenario")
        trainer.load_state_dict(document["trainer"])

    def payload(trainer: Trainer) -> dict[str, Any]:
        return {
            "config": config.to_dict(),
            "scenario": scenario.to_dict(),
            "data": data.describe(),
            "state_dict": trainer.model.state_dict(),
            "trainer": trainer.state_dict(),
            "deployed": trainer.model.parameter_set.to_dict(trainer.model.deployed_raw().detach()),
            "best_epoch": trainer.best_epoch,
            "provenance": run_provenance(),
        }

    def on_epoch(trainer: Trainer, record: EpochRecord) -> None:
        save_checkpoint(checkpoint_path, payload(trainer))

    torch.manual_seed(config.seed)
    trainer.fit(on_epoch=on_epoch, progress=progress)  # restores the best epoch's weights
    save_checkpoint(checkpoint_path, payload(trainer))
    history = _history_frame(trainer.history)
    with atomic_path(out / "history.csv") as tmp:
        history.to_csv(tmp, index=False)
    if plots and len(history):
        plot_losses(history, out / "loss.png", title=f"FlexKalmanNet training on {scenario.name}", best_epoch=trainer.best_epoch)
        plot_parameters(history, out / "parameters.png", title=f"Learned standard deviations ({scenario.name})")
    test = test_split_rmse(model, config, scenario)
    seconds = time.perf_counter() - began
    epochs = history["seconds"] if len(history) else pd.Series(dtype=float)
    training = {
        "config": config.to_dict(),
        "data": data.describe(),
        "epochs_run": len(history),
        "best_epoch": trainer.best_epoch,
        "best_val_loss": trainer.best_loss,
        "seconds_total": seconds,
        "seconds_per_epoch": float(epochs.mean()) if len(epochs) else None,
        **test,
        "history": history_for_artifact(history),
    }
    write_artifact(
        out / "parameters.json",
        estimator="flexkalmannet",
        family=scenario.model_family,
        scenario={"name": scenario.name, "config_hash": scenario.config_hash()},
        estimator_config=deployed_estimator_config(model, config.variant),
        parameters=model.parameter_set.to_dict(model.deployed_raw().detach()),
        training=training,
    )
    return TrainingOutcome(model, config, scenario, history, trainer.best_epoch, out, test, seconds)
