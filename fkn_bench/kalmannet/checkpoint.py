"""The learned-gain filters' models (KalmanNet, Recursive KalmanNet, Split-KalmanNet,
Cholesky-KalmanNet): built fresh from a config for training, or rebuilt from a training checkpoint
(:mod:`fkn_bench.training.checkpoint`; its ``state_dict`` holds the network's weights). Training is
the shared pipeline (:func:`fkn_bench.training.fit`) with their declarations :data:`TRAINABLE`,
:data:`RECURSIVE_TRAINABLE`, :data:`SPLIT_TRAINABLE` and :data:`CHOLESKY_TRAINABLE`.

The process model is the config's (``process_model``: the paper's constant rate by default, or the
rigid body) unless ``build_model`` is given another
:class:`~fkn_bench.models.base.StateSpaceModel` (KalmanNet uses only its common interface).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch

from fkn_bench.models.base import StateSpaceModel
from fkn_bench.kalmannet.cholesky import CholeskyKalmanNet
from fkn_bench.kalmannet.config import CholeskyKalmanNetConfig, KalmanNetConfig, RecursiveKalmanNetConfig, SplitKalmanNetConfig
from fkn_bench.kalmannet.recursion import KalmanNet, ManifoldRecursion
from fkn_bench.kalmannet.recursive import RecursiveKalmanNet
from fkn_bench.kalmannet.split import SplitKalmanNet
from fkn_bench.scenarios import Scenario
from fkn_bench.training import Trainable, TrainingData
from fkn_bench.training.checkpoint import CheckpointError, load_checkpoint

__all__ = ["build_model", "model_from_checkpoint", "TRAINABLE", "build_recursive_model", "recursive_model_from_checkpoint",
           "RECURSIVE_TRAINABLE", "build_split_model", "split_model_from_checkpoint", "SPLIT_TRAINABLE",
           "build_cholesky_model", "cholesky_model_from_checkpoint", "CHOLESKY_TRAINABLE"]


def build_model(config: KalmanNetConfig, data: TrainingData | None = None, *, model: StateSpaceModel | None = None) -> KalmanNet:
    """A fresh KalmanNet (weights seeded by ``config.seed``; the global generator is left as it
    was). ``data`` is not needed (the network sees normalised differences only)."""
    if model is None:  # the config's process model (a known inertia not given: the training scenario's)
        model = config.build_filter(None if data is None else data.scenario).model
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.seed)
        net = KalmanNet(
            model,
            manifold=config.manifold,
            in_mult=config.in_mult,
            out_mult=config.out_mult,
            network_dtype=getattr(torch, config.network_dtype),
            detach_every=config.detach_every,
            initial_gain=config.initial_gain,
            output_scale=config.output_scale,
        )
    return net


def model_from_checkpoint(
    path: str | Path, *, model: StateSpaceModel | None = None
) -> tuple[KalmanNet, KalmanNetConfig, Scenario, dict[str, Any]]:
    """Rebuild the trained KalmanNet of a checkpoint: ``(model, config, scenario, document)``, on
    the process ``model`` it was trained with (default the pose-twist model; the checkpoint records
    the class name and a mismatch is refused)."""
    return _from_checkpoint(path, "kalmannet", KalmanNetConfig, build_model, model)  # type: ignore[return-value]


def _from_checkpoint(
    path: str | Path, estimator: str, config_class: type[KalmanNetConfig],
    build: Callable[..., ManifoldRecursion], model: StateSpaceModel | None,
) -> tuple[ManifoldRecursion, KalmanNetConfig, Scenario, dict[str, Any]]:
    document = load_checkpoint(path)
    if document["estimator"] != estimator:
        raise CheckpointError(f"{path} is a checkpoint of {document['estimator']!r}, not of {estimator}")
    try:
        config = config_class.from_dict(document["config"])
        recorded = document["scenario"]
        scenario = Scenario.from_dict(recorded[0] if isinstance(recorded, list) else recorded)
    except (TypeError, ValueError) as exc:
        raise CheckpointError(f"{path}: invalid config in checkpoint: {exc}") from None
    net = build(config, model=model)
    trained_on = (document.get("deployed") or {}).get("process_model")
    if trained_on is not None and trained_on != type(net.model).__name__:
        raise CheckpointError(f"{path} was trained on process model {trained_on}, not {type(net.model).__name__}")
    try:
        net.load_state_dict(document["state_dict"])
    except RuntimeError as exc:
        raise CheckpointError(f"{path}: weights do not match the checkpoint's config: {exc}") from None
    net.eval()
    return net, config, scenario, document


def build_recursive_model(
    config: RecursiveKalmanNetConfig, data: TrainingData | None = None, *, model: StateSpaceModel | None = None
) -> RecursiveKalmanNet:
    """A fresh Recursive KalmanNet (weights seeded by ``config.seed``; the global generator is
    left as it was), on the config's process model unless ``model`` is given."""
    if model is None:
        model = config.build_filter(None if data is None else data.scenario).model
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.seed)
        net = RecursiveKalmanNet(
            model,
            manifold=config.manifold,
            in_mult=config.in_mult,
            hidden_mult=config.hidden_mult,
            out_mult=config.out_mult,
            network_dtype=getattr(torch, config.network_dtype),
            detach_every=config.detach_every,
            initial_gain=config.initial_gain,
            output_scale=config.output_scale,
            initial_std=config.initial_std,
            std_floor=config.std_floor,
            process_std=config.process_std,
        )
    return net


def recursive_model_from_checkpoint(
    path: str | Path, *, model: StateSpaceModel | None = None
) -> tuple[RecursiveKalmanNet, RecursiveKalmanNetConfig, Scenario, dict[str, Any]]:
    """Rebuild the trained Recursive KalmanNet of a checkpoint (as :func:`model_from_checkpoint`)."""
    return _from_checkpoint(path, "recursive-kalmannet", RecursiveKalmanNetConfig, build_recursive_model,  # type: ignore[return-value]
                            model)


def _build_split(
    cls: type[SplitKalmanNet], config: SplitKalmanNetConfig, data: TrainingData | None, model: StateSpaceModel | None
) -> SplitKalmanNet:
    if model is None:
        model = config.build_filter(None if data is None else data.scenario).model
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.seed)
        net = cls(
            model,
            manifold=config.manifold,
            in_mult=config.in_mult,
            hidden_mult=config.hidden_mult,
            out_mult=config.out_mult,
            network_dtype=getattr(torch, config.network_dtype),
            detach_every=config.detach_every,
            initial_gain=config.initial_gain,  # type: ignore[arg-type]  # (> 0: the config checks it)
            output_scale=config.output_scale,
            std_floor=config.std_floor,
        )
    return net


def build_split_model(
    config: SplitKalmanNetConfig, data: TrainingData | None = None, *, model: StateSpaceModel | None = None
) -> SplitKalmanNet:
    """A fresh Split-KalmanNet (weights seeded by ``config.seed``; the global generator is left
    as it was), on the config's process model unless ``model`` is given."""
    return _build_split(SplitKalmanNet, config, data, model)


def split_model_from_checkpoint(
    path: str | Path, *, model: StateSpaceModel | None = None
) -> tuple[SplitKalmanNet, SplitKalmanNetConfig, Scenario, dict[str, Any]]:
    """Rebuild the trained Split-KalmanNet of a checkpoint (as :func:`model_from_checkpoint`)."""
    return _from_checkpoint(path, "split-kalmannet", SplitKalmanNetConfig, build_split_model, model)  # type: ignore[return-value]


def build_cholesky_model(
    config: CholeskyKalmanNetConfig, data: TrainingData | None = None, *, model: StateSpaceModel | None = None
) -> CholeskyKalmanNet:
    """A fresh Cholesky-KalmanNet (as :func:`build_split_model`)."""
    return _build_split(CholeskyKalmanNet, config, data, model)  # type: ignore[return-value]


def cholesky_model_from_checkpoint(
    path: str | Path, *, model: StateSpaceModel | None = None
) -> tuple[CholeskyKalmanNet, CholeskyKalmanNetConfig, Scenario, dict[str, Any]]:
    """Rebuild the trained Cholesky-KalmanNet of a checkpoint (as :func:`model_from_checkpoint`)."""
    return _from_checkpoint(path, "cholesky-kalmannet", CholeskyKalmanNetConfig, build_cholesky_model,  # type: ignore[return-value]
                            model)


TRAINABLE = Trainable(
    config=KalmanNetConfig.from_options,
    build=build_model,
    notes={"trained_module": "KalmanNet gain network (architecture 2): see checkpoint.pt for the weights"},
)
"""KalmanNet's training declaration (its registry entry's ``trainable``)."""


RECURSIVE_TRAINABLE = Trainable(
    config=RecursiveKalmanNetConfig.from_options,
    build=build_recursive_model,
    notes={"trained_module": "Recursive KalmanNet gain and covariance branches: see checkpoint.pt for the weights"},
)
"""Recursive KalmanNet's training declaration (its registry entry's ``trainable``)."""


SPLIT_TRAINABLE = Trainable(
    config=SplitKalmanNetConfig.from_options,
    build=build_split_model,
    notes={"trained_module": "Split-KalmanNet state and measurement branches: see checkpoint.pt for the weights"},
)
"""Split-KalmanNet's training declaration (its registry entry's ``trainable``)."""


CHOLESKY_TRAINABLE = Trainable(
    config=CholeskyKalmanNetConfig.from_options,
    build=build_cholesky_model,
    notes={"trained_module": "Cholesky-KalmanNet state and measurement branches: see checkpoint.pt for the weights"},
)
"""Cholesky-KalmanNet's training declaration (its registry entry's ``trainable``)."""
