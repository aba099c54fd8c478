"""The numpy online EKF: the torch EKF's twin, to 1e-12 over long sequences."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fkn_bench.envs import generate_episodes
from fkn_bench.filters import ExtendedKalmanFilter, FilterState, online_ekf
from fkn_bench.filters.models import PoseTwistModel
from fkn_bench.scenarios import get_scenario

DT = 0.1


@pytest.mark.parametrize("every", [1, 10])
def test_online_ekf_equals_torch_ekf_over_a_long_sequence(every: int) -> None:
    """2000 steps of ds1-flips (sign flips, outliers) with a measurement every step or every
    10 steps, NaN measurements inside the mask and non-unit quaternions."""
    scenario = get_scenario("ds1-flips", measurement_every=every)
    episodes = generate_episodes(scenario, [5], split="train").window(0, 2000)
    z, valid = episodes.measurements[0].copy(), episodes.valid[0].copy()
    rng = np.random.default_rng(every)
    z[valid, :4] *= rng.uniform(0.5, 2.0, (valid.sum(), 1))
    bad = rng.choice(np.flatnonzero(valid), 20, replace=False)
    z[bad, rng.integers(0, 7, 20)] = np.nan
    variant = ExtendedKalmanFilter()
    noise = variant.layout.default_noise()
    Q, R, P0 = (m.numpy() for m in (noise.process, noise.measurement, noise.initial))
    result = variant.run(noise, torch.from_numpy(z)[None], torch.from_numpy(valid)[None], dt=DT)
    x, P, initialised = None, None, False
    worst_mean = worst_cov = 0.0
    for t in range(len(z)):
        if x is not None:
            x, P = online_ekf.predict(x, P, Q, DT)
        measurement = online_ekf.sanitize_measurement(z[t]) if valid[t] else None
        if measurement is not None:
            if not initialised:
                x, P, initialised = online_ekf.initial_state(measurement), P0.copy(), True
            else:
                x, P, nu, S = online_ekf.update(x, P, measurement, R)
                np.testing.assert_allclose(nu, result.innovations[0, t].numpy(), rtol=0, atol=1e-12)
                np.testing.assert_allclose(S, result.innovation_covariances[0, t].numpy(), rtol=0, atol=1e-12)
        if x is not None:
            worst_mean = max(worst_mean, np.abs(x - result.means[0, t].numpy()).max())
            worst_cov = max(worst_cov, np.abs(P - result.covariances[0, t].numpy()).max())
    assert initialised
    assert worst_mean < 1e-12 and worst_cov < 1e-12, (worst_mean, worst_cov)


def test_predict_and_update_are_pure_and_match_the_model() -> None:
    rng = np.random.default_rng(0)
    x = rng.standard_normal(13)
    x[:4] /= np.linalg.norm(x[:4])
    L = rng.standard_normal((13, 13))
    P = L @ L.T
    Q = np.diag(rng.uniform(1e-6, 1e-4, 13))
    R = np.diag(rng.uniform(1e-3, 1e-2, 7))
    originals = [a.copy() for a in (x, P, Q, R)]
    x_pred, P_pred = online_ekf.predict(x, P, Q, 0.37)
    model = PoseTwistModel()
    np.testing.assert_allclose(x_pred, model.predict(torch.from_numpy(x)[None], 0.37)[0].numpy(), rtol=0, atol=1e-15)
    F = model.jacobian(torch.from_numpy(x)[None], 0.37)[0].numpy()
    np.testing.assert_allclose(P_pred, F @ P @ F.T + Q, rtol=0, atol=1e-12)
    z = np.concatenate((-x[:4], x[4:7] + 0.1))  # opposite sign: aligned before the innovation
    x_post, P_post, nu, S = online_ekf.update(x_pred, P_pred, z, R)
    np.testing.assert_allclose(nu[:4], x[:4] - x_pred[:4], rtol=0, atol=1e-15)
    assert np.linalg.norm(x_post[:4]) == pytest.approx(1.0, abs=1e-15)
    # exact: P_post is symmetrised, 0.5 (M + M^T), the same sum at [i, j] and [j, i]
    np.testing.assert_array_equal(P_post, P_post.T)
    for original, now in zip(originals, (x, P, Q, R)):
        np.testing.assert_array_equal(original, now)  # inputs untouched (exact: no arithmetic on them)
    state, _, _ = ExtendedKalmanFilter().update(FilterState(torch.from_numpy(x_pred)[None], torch.from_numpy(P_pred)[None]), torch.from_numpy(z)[None], torch.from_numpy(R))
    np.testing.assert_allclose(x_post, state.mean[0].numpy(), rtol=0, atol=1e-13)
    P_torch = state.covariance[0].numpy()
    np.testing.assert_allclose(P_post, 0.5 * (P_torch + P_torch.T), rtol=0, atol=1e-12)


def test_update_refuses_an_indefinite_innovation_covariance() -> None:
    x = np.zeros(13)
    x[0] = 1.0
    with pytest.raises(np.linalg.LinAlgError, match="not positive definite"):
        online_ekf.update(x, -np.eye(13), np.concatenate(([1.0, 0, 0, 0], [0, 0, 0])), np.zeros((7, 7)))


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
def test_sanitize_measurement() -> None:
    np.testing.assert_allclose(online_ekf.sanitize_measurement(np.array([0.0, 3.0, 0.0, 4.0, 1.0, 2.0, 3.0])), [0, 0.6, 0, 0.8, 1, 2, 3])
    assert online_ekf.sanitize_measurement(np.array([np.nan] + [0.0] * 6)) is None
    assert online_ekf.sanitize_measurement(np.array([1.0, 0, 0, 0, np.inf, 0, 0])) is None
    assert online_ekf.sanitize_measurement(np.array([0.0, 0, 0, 0, 1, 1, 1])) is None
    assert online_ekf.sanitize_measurement(np.array([1e-7, 0, 0, 0, 1, 1, 1])) is None
    assert online_ekf.sanitize_measurement(np.array([1e160, 1e160, 0, 0, 1, 1, 1])) is None  # |q|^2 overflows
    z = np.array([2.0, 0, 0, 0, 1, 1, 1])
    online_ekf.sanitize_measurement(z)
    assert z[0] == 2.0  # not modified in place


def test_initial_state_and_template_cache() -> None:
    x = online_ekf.initial_state(np.arange(7.0))
    np.testing.assert_array_equal(x, np.concatenate((np.arange(7.0), np.zeros(6))))  # exact: copied
    P = np.eye(13)
    for k in range(40):  # irregular steps must not grow the cache without bound
        online_ekf.predict(x, P, P, 0.1 + k * 1e-3)
    assert len(online_ekf._TEMPLATES) <= 16
