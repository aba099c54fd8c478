"""Split-KalmanNet and Cholesky-KalmanNet (``split-kalmannet``, ``cholesky-kalmannet``) on the
estimator API, untrained and small (the rules hold for any weights): the input rules and the
garbage fuzz, an SPD error covariance on hostile input, online steps that agree with the batch,
finite gradients, the gate on the pose tangent space only, both process models and the Euclidean
manifold, the registry entry (unavailable without weights), and one tiny run of each through the
shared pipeline that deploys as its estimator."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import torch

from fkn_bench.envs import generate_episodes
from fkn_bench.estimators import make_estimator
from fkn_bench.estimators.conformance import check_input_rules, check_survives_garbage, garbage_measurements, hostile_measurements
from fkn_bench.estimators.registry import estimator_spec
from fkn_bench.kalmannet import (
    CHOLESKY_TRAINABLE,
    SPLIT_TRAINABLE,
    CholeskyKalmanNetConfig,
    CholeskyKalmanNetEstimator,
    SplitKalmanNetConfig,
    SplitKalmanNetEstimator,
    build_cholesky_model,
    build_split_model,
    cholesky_model_from_checkpoint,
    split_model_from_checkpoint,
)
from fkn_bench.kalmannet.linear import MODEL as LINEAR_MODEL
from fkn_bench.kalmannet.linear import simulate
from fkn_bench.runtime import torch_threads
from fkn_bench.scenarios import get_scenario
from fkn_bench.training import Sequences, fit
from fkn_bench.training.artifacts import ArtifactError, read_artifact

SMALL = {"in_mult": 2, "hidden_mult": 1, "out_mult": 1}
PEERS = {
    "split-kalmannet": (SplitKalmanNetConfig, build_split_model, SplitKalmanNetEstimator, SPLIT_TRAINABLE,
                        split_model_from_checkpoint),
    "cholesky-kalmannet": (CholeskyKalmanNetConfig, build_cholesky_model, CholeskyKalmanNetEstimator, CHOLESKY_TRAINABLE,
                           cholesky_model_from_checkpoint),
}
FLOOR = 1e-4  # the default std_floor


def _net(name: str, **options):  # noqa: ANN003, ANN202
    config_class, build = PEERS[name][:2]
    return build(config_class(**{**SMALL, **options}))


def _assert_spd(P: np.ndarray) -> None:
    assert np.isfinite(P).all()
    np.testing.assert_array_equal(P, np.swapaxes(P, -1, -2))
    assert np.linalg.eigvalsh(P).min() >= 0.99 * FLOOR**2


@pytest.fixture(scope="module")
def hostile():  # noqa: ANN201
    return hostile_measurements(steps=150)


@pytest.fixture(scope="module", params=sorted(PEERS))
def estimator(request: pytest.FixtureRequest):  # noqa: ANN201
    return PEERS[request.param][2](network=_net(request.param, network_dtype="float64"))


def test_input_rules_garbage_and_an_spd_covariance(estimator, hostile) -> None:  # noqa: ANN001
    estimates = estimator.estimate(hostile.measurements, hostile.mask, hostile.dt)
    B, T = hostile.mask.shape
    assert estimates.means.shape == (B, T, 13) and estimates.covariances.shape == (B, T, 13, 13)
    assert estimates.error_covariances.shape == (B, T, 12, 12) and estimates.innovation_covariances is None
    _assert_spd(estimates.error_covariances)
    check_input_rules(estimator, hostile)
    z, mask = garbage_measurements(hostile.measurements, hostile.mask, np.random.default_rng(0))
    _assert_spd(check_survives_garbage(estimator, z, mask, hostile.dt).error_covariances)


def test_online_steps_agree_with_the_batch(estimator, hostile) -> None:  # noqa: ANN001
    z, mask, dt = hostile.measurements[:, :80], hostile.mask[:, :80], hostile.dt
    batch = estimator.estimate(z, mask, dt)
    for b in range(z.shape[0]):
        estimator.reset(dt=dt)
        steps = [estimator.step({"pose": z[b, t], "valid": mask[b, t]}) for t in range(z.shape[1])]
        np.testing.assert_allclose(np.array([s.mean for s in steps]), batch.means[b], rtol=0, atol=1e-10)
        np.testing.assert_allclose(np.array([s.error_covariance for s in steps]), batch.error_covariances[b], rtol=0, atol=1e-10)
        assert [s.initialised for s in steps] == batch.initialised[b].tolist()
        assert [s.updated for s in steps] == batch.innovation_mask[b].tolist()


@pytest.mark.parametrize("name", sorted(PEERS))
def test_gradients_stay_finite_on_hostile_input(name: str, hostile) -> None:  # noqa: ANN001
    net = _net(name, detach_every=50, network_dtype="float64")
    truth = generate_episodes("ds1-flips", [0, 1, 2], split="test").window(0, 150).truth
    sequences = Sequences(torch.from_numpy(hostile.measurements), torch.from_numpy(hostile.mask), torch.from_numpy(truth))
    net.train()
    objective = net.objectives[0]  # Cholesky-KalmanNet's Gaussian NLL, Split-KalmanNet's MSE
    with torch_threads(1):
        loss, mse = net.sequence_loss(sequences, dt=hostile.dt, loss_cut=60, objective=objective)
        loss.backward()
    assert torch.isfinite(loss) and torch.isfinite(mse)
    for branch in (net.state_branch, net.measurement_branch):  # both branches learn
        assert branch.fc_out[-1].weight.grad.abs().sum() > 0
    grads = [p.grad for p in net.parameters() if p.grad is not None]
    assert all(bool(torch.isfinite(g).all()) for g in grads)
    assert (net.process_raw.grad is not None) == (name == "cholesky-kalmannet")  # Q shapes a trained covariance only
    if name == "split-kalmannet":
        with pytest.raises(ValueError, match="Split-KalmanNet trains with the objectives"):
            net.sequence_loss(sequences, dt=hostile.dt, loss_cut=60, objective="gaussian-nll")


@pytest.mark.parametrize("name", sorted(PEERS))
def test_rigid_body_process_model_and_euclidean_manifold(name: str, hostile) -> None:  # noqa: ANN001
    net = _net(name, process_model="rigid-body", inertia=(0.15, 0.14, 0.16))
    assert net.describe()["process_model"] == "RigidBodyModel" and net.gated
    with torch.no_grad():
        run = net.run(torch.from_numpy(hostile.measurements[:, :60]), torch.from_numpy(hostile.mask[:, :60]), dt=hostile.dt)
    assert torch.isfinite(run.means).all()
    _assert_spd(run.covariances.numpy())
    config_class, build = PEERS[name][:2]
    linear = build(config_class(**SMALL), model=LINEAR_MODEL)
    data = simulate(4, 0)
    with torch.no_grad():
        result = linear.run(data.measurements, data.mask, dt=1.0)
    assert linear.manifold.name == "euclidean" and not linear.gated and result.covariances.shape == (4, 50, 2, 2)
    _assert_spd(result.covariances.numpy())


@pytest.mark.parametrize("name", sorted(PEERS))
def test_config_registered_trainable_and_unavailable_without_weights(name: str, tmp_path, monkeypatch) -> None:  # noqa: ANN001
    from fkn_bench.training import artifacts

    config_class, _, estimator_class, trainable = PEERS[name][:4]
    monkeypatch.setattr(artifacts, "params_dir", lambda package: tmp_path)  # no committed weights
    assert estimator_spec(name).trainable is trainable
    with pytest.raises(ArtifactError, match=f"train one with `fkn-bench train --estimator {name}"):
        make_estimator(name, scenario=get_scenario("ds1"))
    with pytest.raises(ValueError, match="either checkpoint=PATH or network="):
        estimator_class()
    with pytest.raises(ValueError, match="initial_gain > 0"):
        config_class(initial_gain=None)
    assert config_class.from_options({}).objective == ("gaussian-nll" if name == "cholesky-kalmannet" else "supervised")
    with pytest.raises(ValueError, match="unknown .*config keys"):
        config_class.from_options({"initial_std": 0.1})


@pytest.mark.parametrize("name", sorted(PEERS))
def test_fit_writes_its_files_and_deploys_as_the_estimator(name: str, tmp_path) -> None:  # noqa: ANN001
    """``fkn-bench train --estimator NAME --scenario ds1 --epochs 1 --set episodes=1 --set window=100``, cheaply."""
    scenario = get_scenario("ds1", n_steps=300)
    options = {"window": 100, "loss_cut": 20, "episodes": 1, "epochs": 1, "windows_per_batch": 4, "detach_every": 50, **SMALL}
    outcome = fit(name, scenario, options, progress=False, plots=False, out=tmp_path / "run")
    history = pd.read_csv(outcome.out / "history.csv")
    assert list(history["epoch"]) == [1] and np.isfinite(history[["train_loss", "val_loss", "val_rmse"]]).all().all()
    artifact = read_artifact(outcome.artifact)
    assert artifact["parameters"]["architecture"].startswith(name.split("-")[0].capitalize())
    net = PEERS[name][4](outcome.checkpoint)[0]
    assert type(net) is type(outcome.model)
    estimator = make_estimator(name, scenario=scenario, parameters=str(outcome.artifact))
    assert isinstance(estimator, PEERS[name][2]) and estimator.to_config()["checkpoint"] == str(outcome.checkpoint)
    episodes = generate_episodes(scenario, [scenario.dataset_seed], split="test")
    estimates = estimator.estimate(episodes.measurements, episodes.valid, scenario.dt)
    assert np.isfinite(estimates.means).all()
    _assert_spd(estimates.error_covariances)


@pytest.mark.parametrize("name", sorted(PEERS))
def test_zero_outputs_give_the_reference_gain(name: str) -> None:
    """The branches start at the references: ``K = g G`` (``g`` = initial_gain; ``G`` the observed
    gain) and Cholesky-KalmanNet's prior covariance ``P_ref + floor^2 I`` (Split-KalmanNet's
    covariance is the one its gain implies: none from the branches)."""
    net = _net(name, initial_gain=0.3)
    bias = [b.fc_out[-1].bias.detach().to(torch.float64)[None] for b in (net.state_branch, net.measurement_branch)]
    P, K = net.prior_and_gain(*bias)
    np.testing.assert_allclose(K[0].numpy(), 0.3 * net.manifold.observed_gain(), rtol=0, atol=1e-6)  # (float32 bias)
    if name == "split-kalmannet":
        assert P is None
    else:
        np.testing.assert_allclose(P[0].numpy(), net.initial_covariance.numpy() + FLOOR**2 * np.eye(12), rtol=1e-6, atol=1e-14)
