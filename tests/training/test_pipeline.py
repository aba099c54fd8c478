"""The one training pipeline: any registered Trainable is trained by fit() (files, artefact,
estimator), on_epoch sees every epoch and can stop it, and checkpoints are checked on reading."""

from __future__ import annotations

import json

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch

from fkn_bench.estimators import make_estimator, registry
from fkn_bench.filters import ParameterSet, make_filter
from fkn_bench.scenarios import get_scenario
from fkn_bench.training import DirectParameters, Trainable, TrainConfig, fit
from fkn_bench.training.artifacts import TrainedKalmanEstimator, artifact_factory, read_artifact
from fkn_bench.training.checkpoint import CHECKPOINT_FORMAT, CheckpointError, load_checkpoint, save_checkpoint

SHORT = get_scenario("ds1", n_steps=2000)
OPTIONS = {"window": 200, "loss_cut": 50, "episodes": 1, "epochs": 2, "lr": 0.05, "windows_per_batch": 4}
NAME = "pipeline-test-ekf"


@pytest.fixture(scope="module", autouse=True)
def registered() -> Iterator[None]:
    """A third-party trainable estimator: a TrainConfig and free noise parameters."""
    trainable = Trainable(
        config=lambda options: TrainConfig(**{**OPTIONS, **options}),
        build=lambda config, data: DirectParameters(ParameterSet(make_filter(config.variant).layout)),
        notes={"origin": "test"},
    )
    registry.register_estimator(NAME, artifact_factory(NAME), trainable=trainable, overwrite=True)
    yield
    registry._REGISTRY.pop(NAME, None)


def test_fit_trains_any_registered_trainable_estimator(tmp_path: Path) -> None:
    outcome = fit(NAME, SHORT, {}, out=tmp_path, progress=False)
    for name in ("checkpoint.pt", "history.csv", "loss.png", "parameters.png", "parameters.json"):
        assert (tmp_path / name).is_file(), name
    assert list(pd.read_csv(tmp_path / "history.csv")["epoch"]) == [1, 2]
    artifact = read_artifact(outcome.artifact)
    assert artifact["estimator"] == NAME and artifact["training"]["origin"] == "test"
    assert artifact["training"]["history"]["epoch"] == [1, 2] and np.isfinite(artifact["training"]["test_rmse"])
    estimator = make_estimator(NAME, scenario=SHORT, parameters=str(outcome.artifact))
    assert isinstance(estimator, TrainedKalmanEstimator) and estimator.name == NAME
    np.testing.assert_allclose(estimator.q_std, outcome.estimator_config["q_std"])
    assert outcome.summary()["epochs_run"] == 2 and load_checkpoint(outcome.checkpoint)["estimator"] == NAME


def test_on_epoch_sees_every_epoch_and_can_stop_the_training(tmp_path: Path) -> None:
    seen: list[tuple[int, int]] = []

    def on_epoch(epoch: int, history: list) -> bool:
        seen.append((epoch, len(history)))
        return epoch == 2

    outcome = fit(NAME, SHORT, {"epochs": 5}, progress=False, on_epoch=on_epoch)
    assert seen == [(1, 1), (2, 2)] and len(outcome.history) == 2 and outcome.out is None and outcome.test == {}
    with pytest.raises(KeyboardInterrupt):  # an exception (e.g. optuna.TrialPruned) ends it and propagates
        fit(NAME, SHORT, {}, out=tmp_path, progress=False, on_epoch=lambda epoch, history: (_ for _ in ()).throw(KeyboardInterrupt))
    assert load_checkpoint(tmp_path / "checkpoint.pt")["trainer"]["history"][0]["epoch"] == 1  # saved before on_epoch
    with pytest.raises(ValueError, match="not trainable"):
        fit("manual-ekf", SHORT)


def test_corrupt_and_foreign_checkpoints_are_refused(tmp_path: Path) -> None:
    fit(NAME, SHORT, {"epochs": 1}, out=tmp_path, progress=False, plots=False)
    checkpoint = tmp_path / "checkpoint.pt"
    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(checkpoint.read_bytes()[:1000])
    with pytest.raises(CheckpointError, match="truncated or corrupt"):
        load_checkpoint(truncated)
    with pytest.raises(CheckpointError, match="not found"):
        load_checkpoint(tmp_path / "missing.pt")
    foreign = tmp_path / "foreign.pt"
    torch.save({"weights": torch.zeros(3)}, foreign)
    with pytest.raises(CheckpointError, match="not an fkn-bench checkpoint"):
        load_checkpoint(foreign)
    future = tmp_path / "future.pt"
    torch.save({"format": CHECKPOINT_FORMAT, "format_version": 99}, future)
    with pytest.raises(CheckpointError, match="version 99"):
        load_checkpoint(future)
    with pytest.raises(CheckpointError, match="different scenario"):
        fit(NAME, get_scenario("ds1", n_steps=2400), {"epochs": 1}, out=tmp_path, resume=True, progress=False)


def test_checkpoints_are_written_after_the_first_epoch_then_at_most_every_interval(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """After epoch 1, after an epoch once ``CHECKPOINT_INTERVAL_S`` have passed, and at the end
    (here the interval is never reached: 1 + 1 writes for 3 epochs; with no interval, 3 + 1)."""
    from fkn_bench.training import pipeline

    saved: list[int] = []
    real_save = pipeline.save_checkpoint

    def counting_save(path: Path, payload: dict) -> Path:
        saved.append(len(payload["trainer"]["history"]))
        return real_save(path, payload)

    monkeypatch.setattr(pipeline, "save_checkpoint", counting_save)
    monkeypatch.setattr(pipeline, "CHECKPOINT_INTERVAL_S", 1e9)
    fit(NAME, SHORT, {"epochs": 3}, out=tmp_path / "long", progress=False, plots=False)
    assert saved == [1, 3]
    saved.clear()
    monkeypatch.setattr(pipeline, "CHECKPOINT_INTERVAL_S", 0.0)
    fit(NAME, SHORT, {"epochs": 3}, out=tmp_path / "every", progress=False, plots=False)
    assert saved == [1, 2, 3, 3]
    assert load_checkpoint(tmp_path / "every" / "checkpoint.pt")["trainer"]["history"][-1]["epoch"] == 3


def test_a_full_disk_ends_train_in_one_line_and_resume_trusts_only_complete_checkpoints(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Issue 34, finding 4: the disk fills while ``fkn-bench train`` writes its epoch-2 checkpoint
    (torch has written part of it): one line naming the file and the space, exit 2, no torn file;
    ``--resume`` continues from the epoch-1 checkpoint to the uninterrupted run's history. A
    second training into a directory in use is refused (finding 6)."""
    import errno

    from fkn_bench.cli import main
    from fkn_bench.io import directory_lock
    from fkn_bench.training import pipeline, plots

    (tmp_path / "scenarios.toml").write_text('[scenario.tiny-train]\nbase = "ds1"\nn_steps = 2000\n')
    monkeypatch.setattr(pipeline, "CHECKPOINT_INTERVAL_S", 0.0)  # a checkpoint after every epoch
    for figure in ("plot_losses", "plot_parameters"):  # (drawn after the resume: most of the test's time)
        monkeypatch.setattr(plots, figure, lambda *args, **kwargs: None)
    out = tmp_path / "run"
    argv = ["train", "--estimator", NAME, "--scenario", "tiny-train", "--scenario-file", str(tmp_path / "scenarios.toml"),
            "--no-progress", "--out"]  # (2 epochs)
    real_save, saves = torch.save, []

    def full_disk(document: object, path: Path, *args: object, **kwargs: object) -> None:
        saves.append(path)
        if len(saves) == 2:
            Path(path).write_bytes(b"PK\x03\x04 torn")  # what torch leaves before ENOSPC
            raise OSError(errno.ENOSPC, "No space left on device")
        real_save(document, path, *args, **kwargs)

    monkeypatch.setattr(torch, "save", full_disk)
    assert main([*argv, str(out)]) == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and "no space left" in error[0] and str(out / "checkpoint.pt") in error[0], error
    assert not list(out.glob(".*.tmp")) and load_checkpoint(out / "checkpoint.pt")["trainer"]["history"][-1]["epoch"] == 1
    monkeypatch.setattr(torch, "save", real_save)
    with directory_lock(out):
        assert main([*argv, str(out), "--resume"]) == 2
    assert "in use by another fkn-bench process" in capsys.readouterr().err
    saved = load_checkpoint(out / "checkpoint.pt")  # epoch 1 as if it had taken 1000 s
    saved["trainer"]["history"][0]["seconds"] = 1000.0
    save_checkpoint(out / "checkpoint.pt", saved)
    assert main([*argv, str(out), "--resume"]) == 0
    straight = fit(NAME, get_scenario("tiny-train"), {}, progress=False).history.drop(columns="seconds")
    pd.testing.assert_frame_equal(pd.read_csv(out / "history.csv").drop(columns="seconds"), straight, check_exact=True)
    # the resumed run's recorded time includes the epoch run before the interruption
    recorded = json.loads((out / "parameters.json").read_text())["training"]["seconds_total"]
    assert recorded >= 1000.0
