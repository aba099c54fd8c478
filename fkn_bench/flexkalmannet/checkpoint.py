"""FlexKalmanNet checkpoints: build the model from a config, save and load it safely.

A checkpoint is a ``torch.save`` dictionary of plain types and tensors (never a pickled module),
read back with ``torch.load(weights_only=True)``:

``format``, ``format_version``, ``config`` (:class:`FlexKalmanNetConfig` as a dict), ``scenario``
(the training scenario's fields), ``data`` (window/normalisation description), ``state_dict``
(network weights, normalisation statistics, reference measurements), ``trainer`` (optimiser,
scheduler, RNG and history, to resume), ``deployed`` (the learned parameter values with labels
and units), ``best_epoch``, ``provenance``.

Files are written atomically. Loading refuses a missing, truncated or corrupt file, a file of
another format or version, and a state dict that does not fit the config, each with a message
that names the file and the problem.
"""

from __future__ import annotations

import pickle
import zipfile
from pathlib import Path
from typing import Any

import torch

from fkn_bench.filters import ParameterSet, make_filter
from fkn_bench.flexkalmannet.config import FlexKalmanNetConfig
from fkn_bench.flexkalmannet.network import FlexKalmanNet, FlexKalmanNetwork
from fkn_bench.io import atomic_path
from fkn_bench.scenarios import Scenario
from fkn_bench.training import TrainingData

__all__ = [
    "CHECKPOINT_FORMAT",
    "CHECKPOINT_FORMAT_VERSION",
    "CheckpointError",
    "build_model",
    "save_checkpoint",
    "load_checkpoint",
    "model_from_checkpoint",
    "REFERENCE_SAMPLES",
]

CHECKPOINT_FORMAT = "fkn-bench-flexkalmannet"
CHECKPOINT_FORMAT_VERSION = 1
REFERENCE_SAMPLES = 2048
"""Training measurements (a fixed random subset) over which deployed parameters are averaged."""


class CheckpointError(ValueError):
    """A checkpoint that cannot be used (missing, corrupt, wrong format/version, mismatched)."""


def _model_skeleton(config: FlexKalmanNetConfig, reference: torch.Tensor, mean: torch.Tensor, std: torch.Tensor) -> FlexKalmanNet:
    variant = make_filter(config.variant)
    parameter_set = ParameterSet(variant.layout, learn=config.learn, positivity=config.positivity)  # type: ignore[arg-type]
    generator_state = torch.random.get_rng_state()
    torch.manual_seed(config.seed)
    try:
        network = FlexKalmanNetwork(
            parameter_set.size,
            initial_output=parameter_set.initial_values(),
            position_mean=mean,
            position_std=std,
            hidden=config.hidden,
            layers=config.layers,
            activation=config.activation,
            dropout=config.dropout,
            dtype=config.torch_network_dtype,
            output_scale=config.output_scale,
        )
    finally:
        torch.random.set_rng_state(generator_state)
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


def save_checkpoint(path: str | Path, payload: dict[str, Any]) -> Path:
    """Write ``payload`` (see module docstring; format keys are added) atomically."""
    document = {"format": CHECKPOINT_FORMAT, "format_version": CHECKPOINT_FORMAT_VERSION, **payload}
    with atomic_path(path, suffix=".pt") as tmp:
        torch.save(document, tmp)
    return Path(path)


def load_checkpoint(path: str | Path) -> dict[str, Any]:
    """Read and check a checkpoint file; raises :class:`CheckpointError`."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"checkpoint not found: {path}")
    try:
        document = torch.load(path, map_location="cpu", weights_only=True)
    except (RuntimeError, EOFError, OSError, pickle.UnpicklingError, zipfile.BadZipFile, ValueError) as exc:
        raise CheckpointError(f"{path} is not a readable checkpoint (truncated or corrupt?): {exc}") from None
    if not isinstance(document, dict) or document.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointError(f"{path} is not a FlexKalmanNet checkpoint (format '{CHECKPOINT_FORMAT}' expected)")
    version = document.get("format_version")
    if version != CHECKPOINT_FORMAT_VERSION:
        raise CheckpointError(
            f"{path} has checkpoint format version {version!r}; this fkn-bench reads version {CHECKPOINT_FORMAT_VERSION}"
        )
    for key in ("config", "scenario", "state_dict"):
        if key not in document:
            raise CheckpointError(f"{path} lacks '{key}'")
    return document


def model_from_checkpoint(path: str | Path) -> tuple[FlexKalmanNet, FlexKalmanNetConfig, Scenario, dict[str, Any]]:
    """Rebuild the trained model of a checkpoint: ``(model, config, scenario, document)``."""
    document = load_checkpoint(path)
    try:
        config = FlexKalmanNetConfig.from_dict(document["config"])
        scenario = Scenario.from_dict(document["scenario"])
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
