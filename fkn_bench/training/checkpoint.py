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

__all__ = ["CHECKPOINT_FORMAT", "CHECKPOINT_FORMAT_VERSION", "CheckpointError", "save_checkpoint", "load_checkpoint",
           "checked_document"]

CHECKPOINT_FORMAT = "fkn-bench-checkpoint"
CHECKPOINT_FORMAT_VERSION = 1

LEGACY_FORMATS = {"fkn-bench-flexkalmannet": "flexkalmannet"}
"""Formats (version 1) written before the one training pipeline, by estimator: such a checkpoint
is read as a checkpoint of that estimator (the same keys but ``estimator``), so that a network
trained with an older fkn-bench still deploys (``flexkalmannet checkpoint=PATH``)."""


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
    except pickle.UnpicklingError:
        # (torch's own message suggests weights_only=False: unpickling arbitrary code; not relayed)
        raise CheckpointError(f"{path} is not a readable checkpoint: corrupt, or it holds Python objects other than "
                              "tensors and plain data, which fkn-bench does not load") from None
    except (RuntimeError, EOFError, OSError, zipfile.BadZipFile, ValueError) as exc:
        reason = str(exc).strip().splitlines()[0].split(". ")[0] if str(exc).strip() else type(exc).__name__
        if "weights_only" in str(exc):
            reason = "its data cannot be read without unpickling Python objects"
        raise CheckpointError(f"{path} is not a readable checkpoint (truncated or corrupt?): {reason[:200]}") from None
    if isinstance(document, dict) and document.get("format") in LEGACY_FORMATS and "estimator" not in document:
        document = {**document, "format": CHECKPOINT_FORMAT, "estimator": LEGACY_FORMATS[document["format"]]}
    document = checked_document(document, path, CHECKPOINT_FORMAT, CHECKPOINT_FORMAT_VERSION, "an fkn-bench checkpoint",
                                ("estimator", "config", "scenario", "state_dict"), CheckpointError)
    state = document["state_dict"]
    if not isinstance(state, dict):
        raise CheckpointError(f"{path}: 'state_dict' must map names to tensors (got {type(state).__name__})")
    for key, value in state.items():
        if isinstance(value, torch.Tensor) and value.is_floating_point() and not bool(torch.isfinite(value).all()):
            raise CheckpointError(f"{path}: weights {key!r} hold non-finite values (corrupt, or saved from a diverged training)")
    return document


def checked_document(document: Any, path: Path, format: str, version: int, kind: str, required: tuple[str, ...],
                     error: type[ValueError]) -> dict[str, Any]:
    """``document`` when it is a dictionary of ``format`` (``kind``, e.g. "a learned-parameter
    file") at ``version`` with the ``required`` keys; else ``error`` naming the file and problem."""
    if not isinstance(document, dict) or document.get("format") != format:
        raise error(f"{path} is not {kind} (format '{format}' expected)")
    if document.get("format_version") != version:
        raise error(f"{path} has {kind.split(' ', 1)[1]} format version {document.get('format_version')!r}; "
                    f"this fkn-bench reads version {version}")
    for key in required:
        if key not in document:
            raise error(f"{path} lacks '{key}'")
    return document
