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


def test_a_checkpoint_with_non_finite_weights_is_refused_naming_the_tensor(tmp_path: Path) -> None:
    from fkn_bench.training.artifacts import artifact_path, weights_of_artifact
    from fkn_bench.training.checkpoint import save_checkpoint

    document = load_checkpoint(weights_of_artifact(artifact_path("kalmannet", "ds1"), "kalmannet"))
    key = sorted(k for k, v in document["state_dict"].items() if v.is_floating_point())[0]
    state = dict(document["state_dict"])
    state[key] = state[key] * float("inf")
    save_checkpoint(tmp_path / "inf.pt", {**document, "state_dict": state})
    with pytest.raises(CheckpointError, match=rf"inf\.pt: weights '{key}' hold non-finite values"):
        load_checkpoint(tmp_path / "inf.pt")
