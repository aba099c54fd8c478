"""KalmanNet as an estimator: the API's input rules, batch and online paths that agree, no
covariance (and the metrics cope), finite gradients on hostile input, the registry entry."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from fkn_bench.estimators import make_estimator
from fkn_bench.estimators.conformance import check_input_rules, hostile_measurements
from fkn_bench.estimators.registry import estimator_spec
from fkn_bench.models import PoseTwistModel, StateSpaceModel
from fkn_bench.kalmannet import TRAINABLE, KalmanNetConfig, KalmanNetEstimator, build_model
from fkn_bench.metrics import score_run
from fkn_bench.runtime import torch_threads
from fkn_bench.scenarios import get_scenario
from fkn_bench.training.artifacts import ArtifactError


@pytest.fixture(scope="module")
def hostile():  # noqa: ANN201
    return hostile_measurements()


@pytest.fixture(scope="module")
def estimator() -> KalmanNetEstimator:
    """An untrained, seeded float64 KalmanNet: the rules hold for any weights."""
    return KalmanNetEstimator(network=build_model(KalmanNetConfig(network_dtype="float64", out_mult=2)))


def test_kalmannet_follows_the_input_rules(estimator: KalmanNetEstimator, hostile) -> None:
    check_input_rules(estimator, hostile)


def test_online_steps_agree_with_the_batch(estimator: KalmanNetEstimator, hostile) -> None:
    z, mask, dt = hostile.measurements[:, :120], hostile.mask[:, :120], hostile.dt
    batch = estimator.estimate(z, mask, dt)
    assert batch.error_covariances.shape == z.shape[:2] + (12, 12) and batch.innovations is None
    for b in range(z.shape[0]):
        estimator.reset(dt=dt)
        steps = [estimator.step({"pose": z[b, t], "valid": mask[b, t]}) for t in range(z.shape[1])]
        np.testing.assert_allclose(np.array([s.mean for s in steps]), batch.means[b], rtol=0, atol=1e-10)
        np.testing.assert_allclose(np.array([s.native_covariance for s in steps]), batch.error_covariances[b], rtol=1e-9, atol=1e-12)
        assert [s.initialised for s in steps] == batch.initialised[b].tolist()
        assert [s.updated for s in steps] == batch.innovation_mask[b].tolist()


def test_metrics_score_kalmannet_with_its_implied_covariance(estimator: KalmanNetEstimator) -> None:
    """The covariance the gain implies under the manual noise: positive definite, and scored."""
    from fkn_bench.envs import generate_episodes

    episodes = generate_episodes("ds1", [0], split="test").window(0, 400)
    estimates = estimator.estimate(episodes.measurements, episodes.valid, episodes.scenario.dt)
    assert np.linalg.eigvalsh(estimates.error_covariances).min() > 0
    scores = score_run(episodes.truth, estimates.means, episodes.scenario.dt, error_covariances=estimates.error_covariances)
    assert np.isfinite(scores.state_rmse).all() and np.isfinite(scores.nees_mean).all()
    flags = scores.divergence
    assert not (flags.non_finite.any() or flags.cholesky_failed.any())


def test_gradients_stay_finite_on_hostile_input(hostile) -> None:
    net = build_model(KalmanNetConfig(out_mult=2, detach_every=50, network_dtype="float64"))
    net.train()
    with torch_threads(1):
        means = net.run_means(torch.from_numpy(hostile.measurements[:, :150]), torch.from_numpy(hostile.mask[:, :150]), dt=hostile.dt)
        means.square().mean().backward()
    assert torch.isfinite(means).all()
    assert all(p.grad is not None and bool(torch.isfinite(p.grad).all()) for p in net.parameters())


def test_truncated_backpropagation_changes_gradients_not_estimates(hostile) -> None:
    z, mask = torch.from_numpy(hostile.measurements[:1, :120]), torch.from_numpy(hostile.mask[:1, :120])
    grads, means = [], []
    for every in (None, 40):
        net = build_model(KalmanNetConfig(out_mult=2, network_dtype="float64", detach_every=every))
        out = net.run_means(z, mask, dt=hostile.dt)
        out[:, -1].sum().backward()
        grads.append(net.network.fc5[0].weight.grad.clone())
        means.append(out.detach())
    assert torch.equal(means[0], means[1])
    assert not torch.allclose(grads[0], grads[1])


def test_registered_trainable_and_unavailable_without_weights(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:  # noqa: ANN001
    from fkn_bench.training import artifacts

    monkeypatch.setattr(artifacts, "params_dir", lambda package: tmp_path)  # no committed weights
    spec = estimator_spec("kalmannet")
    assert spec.trainable is TRAINABLE
    with pytest.raises(ArtifactError, match="train one with `fkn-bench train --estimator kalmannet"):
        make_estimator("kalmannet", scenario=get_scenario("ds1"))
    with pytest.raises(ValueError, match="either checkpoint=PATH or network="):
        KalmanNetEstimator()


class _InterfaceOnly(StateSpaceModel):
    """Another process model of the pose state, seen only through the common interface (what a
    rigid-body model offers): it delegates each hook to the pose-twist model."""

    state_dim, measurement_dim = 13, 7

    def __init__(self) -> None:
        self._inner = PoseTwistModel()

    def transition(self, x, dt):  # noqa: ANN001, ANN201
        return self._inner.transition(x, dt)

    def measure(self, x):  # noqa: ANN001, ANN201
        return self._inner.measure(x)

    def sanitize(self, measurements, mask):  # noqa: ANN001, ANN201
        return self._inner.sanitize(measurements, mask)

    def align(self, z, x_pred):  # noqa: ANN001, ANN201
        return self._inner.align(z, x_pred)

    def normalize(self, x):  # noqa: ANN001, ANN201
        return self._inner.normalize(x)

    def initial_state(self, z):  # noqa: ANN001, ANN201
        return self._inner.initial_state(z)

    def prior_state(self, batch, dtype):  # noqa: ANN001, ANN201
        return self._inner.prior_state(batch, dtype)


def test_any_process_model_with_the_common_interface_works_unchanged(hostile) -> None:
    config = KalmanNetConfig(network_dtype="float64", out_mult=2)
    z, mask = torch.from_numpy(hostile.measurements[:, :100]), torch.from_numpy(hostile.mask[:, :100])
    with torch.no_grad():
        reference = build_model(config).run_means(z, mask, dt=hostile.dt)
        other = build_model(config, model=_InterfaceOnly())
        assert other.describe()["manifold"] == "pose-tangent" and other.describe()["process_model"] == "_InterfaceOnly"
        torch.testing.assert_close(other.run_means(z, mask, dt=hostile.dt), reference, rtol=0, atol=1e-12)
