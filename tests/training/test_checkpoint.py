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


def test_a_checkpoint_holding_python_objects_is_refused_without_pickle_advice(tmp_path: Path) -> None:
    import fractions

    import torch

    from fkn_bench.training.checkpoint import CheckpointError, load_checkpoint

    path = tmp_path / "objects.pt"
    torch.save({"format": "fkn-bench-checkpoint", "value": fractions.Fraction(1, 3)}, path)
    with pytest.raises(CheckpointError) as info:
        load_checkpoint(path)
    assert str(path) in str(info.value) and "weights_only" not in str(info.value) and "pickle" not in str(info.value).lower()
    (tmp_path / "cut.pt").write_bytes(path.read_bytes()[:40])
    with pytest.raises(CheckpointError, match=r"cut\.pt is not a readable checkpoint \(truncated or corrupt\?\)") as info:
        load_checkpoint(tmp_path / "cut.pt")
    assert "weights_only" not in str(info.value)
