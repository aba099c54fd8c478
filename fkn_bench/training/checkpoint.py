"""Training checkpoints, one format for every trainable estimator.

A checkpoint is a ``torch.save`` dictionary of plain types and tensors (never a pickled module),
read back with ``torch.load(weights_only=True)``:

``format``, ``format_version``, ``estimator`` (registry name), ``config`` (the estimator's training
config as a dict), ``scenario`` (the training scenario's fields), ``data`` (window/normalisation
description), ``state_dict`` (the trained module's weights), ``trainer`` (optimiser, scheduler,
RNG and history, to resume), ``deployed`` (the learned parameter values with labels and units),
``best_epoch``, ``provenance``.

Files are written atomically. Loading refuses a missing, truncated or corrupt file and a file of
another format or version, each with a message that names the file and the problem.
"""

from __future__ import annotations

import pickle
import zipfile
from pathlib import Path
from typing import Any

import torch

from fkn_bench.io import atomic_path

__all__ = ["CHECKPOINT_FORMAT", "CHECKPOINT_FORMAT_VERSION", "CheckpointError", "save_checkpoint", "load_checkpoint"]

CHECKPOINT_FORMAT = "fkn-bench-checkpoint"
CHECKPOINT_FORMAT_VERSION = 1


class CheckpointError(ValueError):
    """A checkpoint that cannot be used (missing, corrupt, wrong format/version, mismatched)."""


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
        raise CheckpointError(f"{path} is not an fkn-bench checkpoint (format '{CHECKPOINT_FORMAT}' expected)")
    version = document.get("format_version")
    if version != CHECKPOINT_FORMAT_VERSION:
        raise CheckpointError(
            f"{path} has checkpoint format version {version!r}; this fkn-bench reads version {CHECKPOINT_FORMAT_VERSION}"
        )
    for key in ("estimator", "config", "scenario", "state_dict"):
        if key not in document:
            raise CheckpointError(f"{path} lacks '{key}'")
    return document
