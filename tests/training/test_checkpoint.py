"""Checkpoints written before the one training pipeline (FlexKalmanNet's own format) still read."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from fkn_bench.training.checkpoint import CHECKPOINT_FORMAT, CheckpointError, load_checkpoint


def test_a_flexkalmannet_checkpoint_of_the_old_format_reads_as_one_of_flexkalmannet(tmp_path: Path) -> None:
    legacy = {"format": "fkn-bench-flexkalmannet", "format_version": 1, "config": {}, "scenario": {}, "state_dict": {}}
    torch.save(legacy, tmp_path / "old.pt")
    document = load_checkpoint(tmp_path / "old.pt")
    assert document["estimator"] == "flexkalmannet" and document["format"] == CHECKPOINT_FORMAT
    torch.save({**legacy, "format_version": 2}, tmp_path / "newer.pt")
    with pytest.raises(CheckpointError, match="version 2"):
        load_checkpoint(tmp_path / "newer.pt")
