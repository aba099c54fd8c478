"""KalmanNet trains through the shared pipeline (``fit``, what ``fkn-bench train --estimator
kalmannet`` runs): files, history with the gradient-step counts, artefact, a trained estimator
from it; and identical runs are identical (fixed seeds)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch

from fkn_bench.estimators import make_estimator
from fkn_bench.kalmannet import KalmanNetConfig, KalmanNetEstimator, model_from_checkpoint
from fkn_bench.scenarios import get_scenario
from fkn_bench.training import fit
from fkn_bench.envs import generate_episodes
from fkn_bench.training.artifacts import ArtifactError, read_artifact

SHORT = get_scenario("ds1", n_steps=2000)
OPTIONS = {"window": 200, "loss_cut": 50, "episodes": 1, "epochs": 2, "windows_per_batch": 4, "out_mult": 2,
           "detach_every": 100}


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> list:
    return [fit("kalmannet", SHORT, OPTIONS, out=tmp_path_factory.mktemp(f"run{i}"), progress=False, plots=False) for i in range(2)]


def test_fit_trains_kalmannet_and_writes_its_files(runs: list) -> None:
    outcome = runs[0]
    for name in ("checkpoint.pt", "history.csv", "parameters.json"):
        assert (outcome.out / name).is_file(), name
    history = pd.read_csv(outcome.out / "history.csv")
    assert list(history["epoch"]) == [1, 2] and np.isfinite(history[["train_loss", "val_loss", "val_rmse"]]).all().all()
    steps = history[["gradient_steps_taken", "gradient_steps_clipped", "gradient_steps_skipped_nonfinite"]].iloc[-1]
    windows = 8  # 1600 train samples / 200
    assert steps["gradient_steps_taken"] == 2 * windows / 4 and steps["gradient_steps_skipped_nonfinite"] == 0
    training = read_artifact(outcome.artifact)["training"]
    assert training["gradient_steps"]["taken"] == steps["gradient_steps_taken"]
    assert training["config"]["detach_every"] == 100 and np.isfinite(training["test_rmse"])
    assert read_artifact(outcome.artifact)["parameters"]["architecture"].startswith("KalmanNet architecture 2")


def test_identical_runs_are_identical(runs: list) -> None:
    first, second = runs
    columns = [c for c in first.history.columns if c != "seconds"]
    pd.testing.assert_frame_equal(first.history[columns], second.history[columns], check_exact=True)
    a, b = (model_from_checkpoint(o.checkpoint)[0].state_dict() for o in runs)
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    assert first.test == second.test


def test_the_trained_network_deploys_as_an_estimator(runs: list) -> None:
    outcome = runs[0]
    from_artifact = make_estimator("kalmannet", scenario=SHORT, parameters=str(outcome.artifact))
    from_checkpoint = make_estimator("kalmannet", checkpoint=str(outcome.checkpoint))
    assert isinstance(from_artifact, KalmanNetEstimator) and from_checkpoint.to_config()["checkpoint"] == str(outcome.checkpoint)
    from fkn_bench.envs import generate_episodes

    episodes = generate_episodes(SHORT, [SHORT.dataset_seed], split="test")
    estimates = from_artifact.estimate(episodes.measurements, episodes.valid, SHORT.dt)
    with torch.no_grad():
        direct = outcome.model.run_means(torch.as_tensor(episodes.measurements), torch.as_tensor(episodes.valid), dt=SHORT.dt)
    np.testing.assert_allclose(estimates.means[..., 4:], direct.numpy()[..., 4:], rtol=1e-5, atol=1e-9)  # deployed: the float32 network evaluated in float64


def test_config_refuses_what_kalmannet_does_not_train_with() -> None:
    with pytest.raises(ValueError, match="unknown KalmanNet config keys"):
        KalmanNetConfig.from_options({"variant": "ukf"})
    with pytest.raises(ValueError, match="detach_every"):
        KalmanNetConfig(detach_every=0)
    assert KalmanNetConfig.from_options({}).to_dict()["max_grad_norm"] == 1.0


def test_installed_weights_deploy_and_a_corrupt_file_is_refused(runs: list, tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """``fkn-bench train --write-artifact`` (:func:`install_artifact`) of a network: the artefact
    plus a weights file beside it (no optimiser state), checked by its SHA-256; the registry's
    factory loads it for the scenario's family and names a missing or corrupt file."""
    from fkn_bench.training import artifacts

    outcome = runs[0]
    monkeypatch.setattr(artifacts, "params_dir", lambda package: tmp_path / package)
    with pytest.raises(ArtifactError, match="no trained KalmanNet for model family 'ds1'.*--write-artifact"):
        make_estimator("kalmannet", scenario=get_scenario("ds1"))
    installed = artifacts.install_artifact(outcome.artifact, "kalmannet", "ds1")
    weights = tmp_path / "fkn_bench.kalmannet" / "kalmannet-ds1.weights.pt"
    assert installed == weights.with_name("kalmannet-ds1.json") and weights.is_file()
    assert set(read_artifact(installed)["estimator_config"]) == {"weights", "weights_sha256"}
    assert "trainer" not in torch.load(weights, weights_only=True)  # weights only, no optimiser state
    assert weights.stat().st_size < outcome.checkpoint.stat().st_size
    committed = make_estimator("kalmannet", scenario=get_scenario("ds1"))
    trained = make_estimator("kalmannet", checkpoint=str(outcome.checkpoint))
    episodes = generate_episodes(SHORT, [0], split="test")
    np.testing.assert_array_equal(committed.estimate(episodes.measurements, episodes.valid, SHORT.dt).means,
                                  trained.estimate(episodes.measurements, episodes.valid, SHORT.dt).means)
    assert committed.to_config()["checkpoint"] == "fkn_bench.kalmannet/params/kalmannet-ds1.weights.pt"
    assert KalmanNetEstimator(**committed.to_config()).to_config() == committed.to_config()
    data = bytearray(weights.read_bytes())
    data[len(data) // 2] ^= 0xFF
    weights.write_bytes(bytes(data))
    with pytest.raises(ArtifactError, match="does not match .*SHA-256 differs"):
        make_estimator("kalmannet", scenario=get_scenario("ds1"))
    weights.unlink()
    with pytest.raises(ArtifactError, match="weights file .* is missing"):
        make_estimator("kalmannet", scenario=get_scenario("ds1"))


def test_a_config_file_value_out_of_range_is_refused_naming_the_file(tmp_path) -> None:  # type: ignore[no-untyped-def]
    """A KalmanNet TOML whose value has the right kind but is out of range (``manifold``, ``epochs
    = 0``) or whose key is unknown is refused naming the file (issue 34, finding 5: the range
    errors did not say which file)."""
    import pytest

    from fkn_bench.kalmannet.config import KalmanNetConfig

    path = tmp_path / "kn.toml"
    for text, message in (('manifold = "sphere"\n', "manifold must be"), ("epochs = 0\n", "epochs must be >= 1"),
                          ("epoch = 3\n", "unknown KalmanNet config keys")):
        path.write_text(text)
        with pytest.raises(ValueError, match=rf"^{path}: {message}"):
            KalmanNetConfig.from_toml(path)
