"""The offline-tuned EKFs: maximum-likelihood recovery of known noise, the fit end to end
(outputs, artefact, resume, CLI), the committed artefacts and the estimators built from them."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
import torch

from fkn_bench.baselines.tuned import TUNED_OBJECTIVES, TunedEKFEstimator, tuned_config
from fkn_bench.envs import generate_episodes
from fkn_bench.estimators import estimator_spec, load_estimator, make_estimator
from fkn_bench.filters import ExtendedKalmanFilter, ParameterSet
from fkn_bench.flexkalmannet.config import FlexKalmanNetConfig
from fkn_bench.scenarios import get_scenario
from fkn_bench.training import DirectParameters, Sequences, TrainConfig, Trainer, fit
from fkn_bench.training.artifacts import artifact_path, read_artifact

pytestmark = pytest.mark.slow(seconds=12)  # trainings of the tuned EKFs

SHORT = get_scenario("ds1", n_steps=2000)
TINY = {"epochs": 2, "window": 200, "loss_cut": 50, "lbfgs_iterations": 3}


# ---------------------------------------------------------------------------- ML recovery
def _sequences(cv, batch: int, steps: int, seed: int) -> Sequences:  # noqa: ANN001
    truth, z = cv.simulate(batch, steps, seed)
    return Sequences(torch.from_numpy(z), torch.ones(batch, steps, dtype=torch.bool), torch.from_numpy(truth))


def test_nll_tuning_recovers_the_true_noise(balanced) -> None:
    """20 000 samples (200 sequences of 100 steps, the first 10 steps of each cut) of a
    constant-velocity model with known noise: minimising the innovation NLL of the EKF (the KF on
    a linear model) over the six log standard deviations, from unit starting values, recovers
    every standard deviation within 10%."""
    cv = balanced
    variant = ExtendedKalmanFilter(model=cv.torch_model())
    parameter_set = ParameterSet(variant.layout)
    model = DirectParameters(parameter_set)
    data = SimpleNamespace(window=100, scenario=SimpleNamespace(dt=cv.dt), train=_sequences(cv, 200, 100, 0), val=_sequences(cv, 10, 100, 1))
    config = TrainConfig(objective="nll", optimizer="lbfgs", lbfgs_iterations=40, lr=1.0, epochs=3, patience=1, loss_cut=10)
    trainer = Trainer(model, variant, data, config)  # type: ignore[arg-type]
    trainer.fit(progress=False)
    with torch.no_grad():
        fitted = parameter_set.to_dict(model.deployed_raw())["entries"]
    q, r = np.array(fitted["q_std"]["std"]), np.array(fitted["r_std"]["std"])
    assert np.abs(q / cv.q - 1).max() < 0.10, q
    assert np.abs(r / cv.r - 1).max() < 0.10, r


# ---------------------------------------------------------------------------- fitting end to end
@pytest.fixture(scope="module")
def fits(tmp_path_factory: pytest.TempPathFactory):  # noqa: ANN201
    out = {}
    for name, optimizer in (("direct-tuned-ekf", "lbfgs"), ("nll-tuned-ekf", "adam")):
        config = tuned_config(name, {"optimizer": optimizer, **TINY})
        out[name] = fit(name, SHORT, config, out=tmp_path_factory.mktemp(name), progress=False)
    return out


@pytest.mark.parametrize("name", sorted(TUNED_OBJECTIVES))
def test_fit_writes_history_plots_checkpoint_and_artifact(name: str, fits) -> None:
    outcome = fits[name]
    for file in ("checkpoint.pt", "history.csv", "loss.png", "parameters.png", "parameters.json"):
        assert (outcome.out / file).is_file(), file
    history = pd.read_csv(outcome.out / "history.csv")
    assert list(history["epoch"]) == [1, 2]
    assert {"train_loss", "val_loss", "val_rmse", "sigma_Q_qw", "sigma_R_rz"} <= set(history.columns)
    artifact = read_artifact(outcome.artifact)
    assert artifact["estimator"] == name and artifact["family"] == "ds1"
    assert artifact["training"]["objective"] == TUNED_OBJECTIVES[name]
    assert artifact["training"]["data"]["window"] == 200 and np.isfinite(artifact["training"]["test_rmse"])
    assert "git_commit" in artifact["provenance"] and "torch" in artifact["provenance"]
    assert len(artifact["estimator_config"]["q_std"]) == 13 and len(artifact["estimator_config"]["r_std"]) == 7
    estimator = make_estimator(name, scenario=SHORT, parameters=str(outcome.artifact))
    assert isinstance(estimator, TunedEKFEstimator) and estimator.name == name
    np.testing.assert_allclose(estimator.q_std, outcome.estimator_config["q_std"], rtol=1e-12)
    episodes = generate_episodes(SHORT, [1], split="test")
    assert np.isfinite(estimator.estimate(episodes.measurements, episodes.valid, SHORT.dt).means).all()


def test_the_nll_fit_uses_no_ground_truth(fits) -> None:
    """Model selection of the NLL fit is on the validation NLL, never the RMSE against truth."""
    history = pd.read_csv(fits["nll-tuned-ekf"].out / "history.csv")
    best = int(history["val_loss"].idxmin())
    assert int(history.loc[best, "epoch"]) == fits["nll-tuned-ekf"].best_epoch
    assert (history["val_loss"] < 0).all()  # an NLL per update, not an RMSE


@pytest.mark.parametrize("optimizer", ["lbfgs", "adam"])
def test_fit_resumes(optimizer: str, tmp_path: Path) -> None:
    config = tuned_config("direct-tuned-ekf", {"optimizer": optimizer, **TINY, "epochs": 1})
    fit("direct-tuned-ekf", SHORT, config, out=tmp_path, progress=False)
    with pytest.raises(ValueError, match="another estimator or a different config"):
        fit("direct-tuned-ekf", SHORT, {"optimizer": optimizer, **TINY}, out=tmp_path, resume=True, progress=False)
    with pytest.raises(ValueError, match="another estimator"):
        fit("nll-tuned-ekf", SHORT, {"optimizer": optimizer, **TINY, "epochs": 1}, out=tmp_path, resume=True, progress=False)
    again = fit("direct-tuned-ekf", SHORT, config, out=tmp_path, resume=True, progress=False)
    assert len(again.history) == 1  # already at its epoch budget: nothing more to do
    with pytest.raises(ValueError, match="checkpoint not found"):
        fit("direct-tuned-ekf", SHORT, config, out=tmp_path / "fresh", resume=True, progress=False)


def test_configuration_defaults_and_checks() -> None:
    resolved = tuned_config("nll-tuned-ekf", {})
    fkn = FlexKalmanNetConfig()
    assert (resolved.window, resolved.stride, resolved.train_measurement_every, resolved.episodes, resolved.loss_cut,
            resolved.windows_per_batch) == (
        fkn.window, fkn.stride, fkn.train_measurement_every, fkn.episodes, fkn.loss_cut, fkn.windows_per_batch
    )
    assert (resolved.objective, resolved.optimizer, resolved.lr, resolved.epochs, resolved.patience) == ("nll", "lbfgs", 1.0, 15, 2)
    adam = tuned_config("direct-tuned-ekf", {"optimizer": "adam"})
    assert (adam.objective, adam.lr, adam.epochs, adam.patience) == ("supervised", 0.05, 150, 20)
    assert tuned_config("direct-tuned-ekf", {"optimizer": "adam", "lr": 0.1}).lr == 0.1
    with pytest.raises(ValueError, match="trained with objective 'nll'"):
        tuned_config("nll-tuned-ekf", {"objective": "supervised"})
    with pytest.raises(ValueError, match="unknown direct-tuned-ekf training options"):
        tuned_config("direct-tuned-ekf", {"hidden": 3})
    with pytest.raises(ValueError, match="variant 'ekf'"):
        tuned_config("direct-tuned-ekf", {"variant": "ukf"})
    with pytest.raises(ValueError, match="optimizer must be one of"):
        tuned_config("direct-tuned-ekf", {"optimizer": "sgd"})


def test_cli_trains_and_installs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    from fkn_bench.cli import main
    from fkn_bench.scenarios import registry
    from fkn_bench.training import artifacts

    # --scenario-file registers the scenario for the process: keep it out of the named scenarios
    # that later tests (the harness, the gates) enumerate
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    scenario_file = tmp_path / "short.toml"
    scenario_file.write_text('[scenario.ds1-short]\nbase = "ds1"\nn_steps = 2000\n')
    monkeypatch.setattr(artifacts, "artifact_path", lambda estimator, family: tmp_path / "params" / f"{estimator}-{family}.json")
    options = ["--set", "window=200", "--set", "loss_cut=50", "--set", "lbfgs_iterations=2", "--epochs", "1"]
    code = main(["train", "--estimator", "nll-tuned-ekf", "--scenario", "ds1-short", "--scenario-file", str(scenario_file),
                 "--out", str(tmp_path / "run"), "--no-progress", "--json", "--write-artifact", *options])
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["estimator"] == "nll-tuned-ekf" and summary["epochs_run"] == 1
    assert read_artifact(tmp_path / "params" / "nll-tuned-ekf-ds1.json")["scenario"]["name"] == "ds1-short"
    assert estimator_spec("direct-tuned-ekf").trainable and estimator_spec("nll-tuned-ekf").trainable


# ---------------------------------------------------------------------------- committed artefacts
@pytest.mark.parametrize("name", sorted(TUNED_OBJECTIVES))
@pytest.mark.parametrize("family", ["ds1", "ds2"])
def test_committed_artifacts_run_out_of_the_box(name: str, family: str, tmp_path: Path) -> None:
    path = artifact_path(name, family)
    artifact = read_artifact(path)
    assert artifact["estimator"] == name and artifact["family"] == family
    assert artifact["training"]["objective"] == TUNED_OBJECTIVES[name] and artifact["scenario"]["name"] == family
    assert {"git_commit", "python", "command"} <= set(artifact["provenance"])
    scenario = get_scenario("ds2" if family == "ds2" else "ds1-noise5x")  # family members
    assert scenario.model_family == family
    estimator = make_estimator(name, scenario=scenario)
    assert estimator.metadata["artifact"] == f"fkn_bench.baselines/params/{name}-{family}.json"  # location-independent
    np.testing.assert_allclose(estimator.q_std, artifact["estimator_config"]["q_std"])
    again = load_estimator(estimator.save(tmp_path / "tuned.json"))
    assert isinstance(again, TunedEKFEstimator) and again.to_config() == estimator.to_config()
