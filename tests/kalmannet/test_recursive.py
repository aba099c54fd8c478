"""Recursive KalmanNet (``recursive-kalmannet``; Mortada et al., EUSIPCO 2025): the gate, shapes, a
covariance that is symmetric positive definite and finite whatever the input, batch and online
paths that agree, NEES scored by the metrics, both objectives through the shared pipeline with
their files and fixed seeds, the registry entry (unavailable without weights), both process
models and the Euclidean manifold."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import torch

from fkn_bench.envs import generate_episodes
from fkn_bench.estimators import load_estimator, make_estimator
from fkn_bench.estimators.conformance import check_input_rules, hostile_measurements
from fkn_bench.estimators.registry import estimator_spec
from fkn_bench.kalmannet import (
    RECURSIVE_TRAINABLE,
    KalmanNetConfig,
    RecursiveKalmanNet,
    RecursiveKalmanNetConfig,
    RecursiveKalmanNetEstimator,
    build_model,
    build_recursive_model,
    recursive_model_from_checkpoint,
)
from fkn_bench.kalmannet.linear import MODEL as LINEAR_MODEL
from fkn_bench.kalmannet.linear import simulate
from fkn_bench.metrics import score_run
from fkn_bench.runtime import torch_threads
from fkn_bench.scenarios import get_scenario
from fkn_bench.training import Sequences, fit
from fkn_bench.training.artifacts import ArtifactError, read_artifact

SMALL = {"in_mult": 2, "hidden_mult": 1, "out_mult": 1}
SHORT = get_scenario("ds1", n_steps=1000)
OPTIONS = {"window": 100, "loss_cut": 20, "episodes": 1, "epochs": 1, "windows_per_batch": 4, "detach_every": 50, **SMALL}


@pytest.fixture(scope="module")
def hostile():  # noqa: ANN201
    return hostile_measurements()


@pytest.fixture(scope="module")
def estimator() -> RecursiveKalmanNetEstimator:
    """An untrained, seeded float64 Recursive KalmanNet: the rules hold for any weights."""
    return RecursiveKalmanNetEstimator(network=build_recursive_model(RecursiveKalmanNetConfig(network_dtype="float64", **SMALL)))


def _assert_spd(P: np.ndarray, floor: float) -> None:
    assert np.isfinite(P).all()
    np.testing.assert_array_equal(P, np.swapaxes(P, -1, -2))
    assert np.linalg.eigvalsh(P).min() >= 0.99 * floor**2


def test_shapes_and_a_positive_definite_covariance_on_hostile_input(estimator: RecursiveKalmanNetEstimator, hostile) -> None:
    """NaN, inf and zero quaternions, rescaled and sign-flipped quaternions, outliers, dropouts
    and a late start (the conformance batch): finite means, SPD covariances everywhere."""
    estimates = estimator.estimate(hostile.measurements, hostile.mask, hostile.dt)
    B, T = hostile.mask.shape
    assert estimates.means.shape == (B, T, 13) and estimates.covariances.shape == (B, T, 13, 13)
    assert estimates.error_covariances.shape == (B, T, 12, 12) and estimates.innovation_covariances is None
    assert np.isfinite(estimates.means).all() and np.isfinite(estimates.covariances).all()
    _assert_spd(estimates.error_covariances, 1e-4)
    # the paper's default initialisation (no starting gain, full output weights) is still SPD
    wild = build_recursive_model(RecursiveKalmanNetConfig(initial_gain=None, output_scale=1.0, **SMALL))
    with torch.no_grad():
        run = wild.run(torch.from_numpy(hostile.measurements), torch.from_numpy(hostile.mask), dt=hostile.dt)
    assert torch.isfinite(run.means).all()
    _assert_spd(run.covariances.numpy(), 1e-4)


def test_recursive_kalmannet_follows_the_input_rules(estimator: RecursiveKalmanNetEstimator, hostile) -> None:
    check_input_rules(estimator, hostile)


def test_online_steps_agree_with_the_batch(estimator: RecursiveKalmanNetEstimator, hostile) -> None:
    z, mask, dt = hostile.measurements[:, :120], hostile.mask[:, :120], hostile.dt
    batch = estimator.estimate(z, mask, dt)
    for b in range(z.shape[0]):
        estimator.reset(dt=dt)
        steps = [estimator.step({"pose": z[b, t], "valid": mask[b, t]}) for t in range(z.shape[1])]
        np.testing.assert_allclose(np.array([s.mean for s in steps]), batch.means[b], rtol=0, atol=1e-10)
        np.testing.assert_allclose(np.array([s.error_covariance for s in steps]), batch.error_covariances[b], rtol=0, atol=1e-10)
        np.testing.assert_allclose(np.array([s.covariance for s in steps]), batch.covariances[b], rtol=0, atol=1e-10)
        assert [s.initialised for s in steps] == batch.initialised[b].tolist()
        assert [s.updated for s in steps] == batch.innovation_mask[b].tolist()
        assert steps[-1].native_covariance.shape == (12, 12)


def test_metrics_score_its_nees(estimator: RecursiveKalmanNetEstimator) -> None:
    episodes = generate_episodes("ds1", [0], split="test").window(0, 300)
    estimates = estimator.estimate(episodes.measurements, episodes.valid, episodes.scenario.dt)
    scores = score_run(episodes.truth, estimates.means, episodes.scenario.dt, error_covariances=estimates.error_covariances)
    assert np.isfinite(scores.nees_mean).all() and np.isnan(scores.nis_mean).all()
    assert not (scores.divergence.non_finite.any() or scores.divergence.cholesky_failed.any())


@pytest.mark.parametrize("objective", ["gaussian-nll", "supervised"])
def test_gradients_stay_finite_on_hostile_input(objective: str, hostile) -> None:
    net = build_recursive_model(RecursiveKalmanNetConfig(detach_every=50, network_dtype="float64", **SMALL))
    truth = generate_episodes("ds1-flips", [0, 1, 2], split="test").window(0, 150).truth
    sequences = Sequences(torch.from_numpy(hostile.measurements[:, :150]), torch.from_numpy(hostile.mask[:, :150]),
                          torch.from_numpy(truth))
    net.train()
    with torch_threads(1):
        loss, mse = net.sequence_loss(sequences, dt=hostile.dt, loss_cut=60, objective=objective)
        loss.backward()
    assert torch.isfinite(loss) and torch.isfinite(mse)
    grads = [p.grad for p in net.parameters() if p.grad is not None]
    assert grads and all(bool(torch.isfinite(g).all()) for g in grads)
    if objective == "gaussian-nll":  # the covariance branch learns from the NLL only
        assert net.covariance_branch.fc_out[-1].weight.grad.abs().sum() > 0
    with pytest.raises(ValueError, match="objectives"):
        net.sequence_loss(sequences, dt=hostile.dt, loss_cut=60, objective="nll")


def test_rigid_body_process_model_and_euclidean_manifold(hostile) -> None:
    config = RecursiveKalmanNetConfig(process_model="rigid-body", inertia=(0.15, 0.14, 0.16), **SMALL)
    net = build_recursive_model(config)
    assert net.describe()["process_model"] == "RigidBodyModel"
    with torch.no_grad():
        run = net.run(torch.from_numpy(hostile.measurements[:, :60]), torch.from_numpy(hostile.mask[:, :60]), dt=hostile.dt)
    assert torch.isfinite(run.means).all()
    _assert_spd(run.covariances.numpy(), 1e-4)
    linear = build_recursive_model(RecursiveKalmanNetConfig(**SMALL), model=LINEAR_MODEL)
    data = simulate(4, 0)
    with torch.no_grad():
        result = linear.run(data.measurements, data.mask, dt=1.0)
    assert linear.manifold.name == "euclidean" and result.covariances.shape == (4, 50, 2, 2)
    _assert_spd(result.covariances.numpy(), 1e-4)


def test_config_objectives_and_kalmannet_unchanged() -> None:
    assert RecursiveKalmanNetConfig.from_options({}).objective == "gaussian-nll"
    assert RecursiveKalmanNetConfig.from_options({"objective": "supervised"}).to_dict()["objective"] == "supervised"
    with pytest.raises(ValueError, match="gaussian-nll or supervised"):
        RecursiveKalmanNetConfig(objective="nll")
    with pytest.raises(ValueError, match="unknown Recursive KalmanNet config keys"):
        RecursiveKalmanNetConfig.from_options({"variant": "ukf"})
    with pytest.raises(ValueError, match="initial_std > std_floor"):
        RecursiveKalmanNetConfig(std_floor=0.0)
    with pytest.raises(ValueError, match="supervised objective"):
        KalmanNetConfig(objective="gaussian-nll")
    kalmannet = build_model(KalmanNetConfig(out_mult=2))
    with pytest.raises(ValueError, match="objectives"):
        kalmannet.sequence_loss(simulate(1, 0), dt=1.0, loss_cut=0, objective="gaussian-nll")


def test_registered_trainable_and_unavailable_without_weights(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:  # noqa: ANN001
    from fkn_bench.training import artifacts

    monkeypatch.setattr(artifacts, "params_dir", lambda package: tmp_path)  # no committed weights
    spec = estimator_spec("recursive-kalmannet")
    assert spec.trainable is RECURSIVE_TRAINABLE
    with pytest.raises(ArtifactError, match="train one with `fkn-bench train --estimator recursive-kalmannet"):
        make_estimator("recursive-kalmannet", scenario=get_scenario("ds1"))
    with pytest.raises(ValueError, match="either checkpoint=PATH or network="):
        RecursiveKalmanNetEstimator()


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list]:
    """Two identical Gaussian-NLL runs and one supervised run through ``fit``."""
    out: dict[str, list] = {}
    for objective, repeats in (("gaussian-nll", 2), ("supervised", 1)):
        out[objective] = [fit("recursive-kalmannet", SHORT, {**OPTIONS, "objective": objective}, progress=False, plots=False,
                              out=tmp_path_factory.mktemp(f"{objective}{i}")) for i in range(repeats)]
    return out


@pytest.mark.parametrize("objective", ["gaussian-nll", "supervised"])
def test_fit_with_each_objective_writes_its_files(runs: dict[str, list], objective: str) -> None:
    outcome = runs[objective][0]
    for name in ("checkpoint.pt", "history.csv", "parameters.json"):
        assert (outcome.out / name).is_file(), name
    history = pd.read_csv(outcome.out / "history.csv")
    assert list(history["epoch"]) == [1] and np.isfinite(history[["train_loss", "val_loss", "val_rmse"]]).all().all()
    assert history["gradient_steps_skipped_nonfinite"].iloc[-1] == 0
    artifact = read_artifact(outcome.artifact)
    assert artifact["training"]["objective"] == objective and np.isfinite(artifact["training"]["test_rmse"])
    assert artifact["training"]["val_loss_is"] == ("Gaussian NLL of the state error per step" if objective == "gaussian-nll"
                                                   else "13-state RMSE")
    assert artifact["parameters"]["architecture"].startswith("Recursive KalmanNet")
    net, config, _, _ = recursive_model_from_checkpoint(outcome.checkpoint)
    assert isinstance(net, RecursiveKalmanNet) and config.objective == objective


def test_identical_runs_are_identical(runs: dict[str, list]) -> None:
    first, second = runs["gaussian-nll"]
    columns = [c for c in first.history.columns if c != "seconds"]
    pd.testing.assert_frame_equal(first.history[columns], second.history[columns], check_exact=True)
    a, b = (recursive_model_from_checkpoint(o.checkpoint)[0].state_dict() for o in (first, second))
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    assert first.test == second.test


def test_the_trained_network_deploys_as_an_estimator(runs: dict[str, list], tmp_path) -> None:  # noqa: ANN001
    outcome = runs["gaussian-nll"][0]
    estimator = make_estimator("recursive-kalmannet", scenario=SHORT, parameters=str(outcome.artifact))
    assert isinstance(estimator, RecursiveKalmanNetEstimator)
    assert estimator.to_config()["checkpoint"] == str(outcome.checkpoint)
    reloaded = load_estimator(estimator.save(tmp_path / "rkn.json"))
    assert isinstance(reloaded, RecursiveKalmanNetEstimator) and reloaded.to_config() == estimator.to_config()
    episodes = generate_episodes(SHORT, [SHORT.dataset_seed], split="test")
    estimates = estimator.estimate(episodes.measurements, episodes.valid, SHORT.dt)
    with torch.no_grad():
        direct = outcome.model.run(torch.as_tensor(episodes.measurements), torch.as_tensor(episodes.valid), dt=SHORT.dt)
    np.testing.assert_allclose(estimates.means[..., 4:], direct.means.numpy()[..., 4:], rtol=1e-5, atol=1e-9)  # deployed: float32 weights evaluated in float64
    np.testing.assert_allclose(estimates.error_covariances, direct.covariances.numpy(), rtol=1e-5, atol=1e-9)


def test_the_gate_keeps_a_wild_gain_in_range() -> None:
    """Untrained with PyTorch's default initialisation, the gain runs away on five times the
    noise when every measurement is used (as in training, with gradients recorded); gated (where
    it estimates) its runaway updates are refused and the track restarts: it stays bounded."""
    torch.manual_seed(0)
    wild = build_recursive_model(RecursiveKalmanNetConfig(initial_gain=None, output_scale=1.0, **SMALL))
    episodes = generate_episodes("ds1-noise5x", [0], split="test").window(0, 450)
    z, mask = torch.from_numpy(episodes.measurements), torch.from_numpy(episodes.valid)
    with torch.enable_grad():
        ungated = wild.run(z, mask, dt=episodes.scenario.dt)
    with torch.no_grad():
        gated = wild.run(z, mask, dt=episodes.scenario.dt)
    assert ungated.means.abs().max() > 1e6
    assert gated.means.abs().max() < 1e3
    assert gated.initialised.all(1).all() and gated.updated.sum() < ungated.updated.sum()


def test_a_correction_no_kalman_gain_could_make_is_refused() -> None:
    """``d = K nu`` with the Kalman gain has ``d^T P^-1 d <= nu^T S^-1 nu``; twenty times that
    gain does not."""
    from types import SimpleNamespace

    rng = np.random.default_rng(0)
    net = build_recursive_model(RecursiveKalmanNetConfig(**SMALL))
    A = rng.normal(size=(12, 12))
    P = torch.from_numpy(A @ A.T / 12 + 0.01 * np.eye(12))[None]
    S = net.innovation_covariance(SimpleNamespace(covariance=P))
    H = torch.from_numpy(net.manifold.measurement_matrix())
    K = P @ H.T @ torch.linalg.inv(S)
    nu = torch.from_numpy(rng.normal(size=(1, 6)))
    nis = float((nu * torch.linalg.solve(S, nu[..., None])[..., 0]).sum())
    prior = SimpleNamespace(covariance=P)
    assert net.plausible_correction(prior, SimpleNamespace(correction=(K @ nu[..., None])[..., 0]), nis).item()
    assert not net.plausible_correction(prior, SimpleNamespace(correction=20 * (K @ nu[..., None])[..., 0]), nis).item()
