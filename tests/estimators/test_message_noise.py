"""Each step's R from the covariance its measurement states: validation, the 6- and 7-dim forms,
and a Kalman estimator that follows a noise step it is told about."""

from __future__ import annotations

import numpy as np
import pytest

from fkn_bench.envs import generate_episodes
from fkn_bench.estimators.kalman import KalmanEstimator
from fkn_bench.estimators.message_noise import message_noise, usable_covariances
from fkn_bench.geometry.quaternion import theta_matrix
from fkn_bench.metrics import component_errors, state_rmse
from fkn_bench.scenarios import get_scenario


def test_only_finite_symmetric_positive_definite_covariances_are_used() -> None:
    good = np.diag([0.01] * 3 + [0.04] * 3)
    asymmetric = good.copy()
    asymmetric[0, 1] = 1e-3
    indefinite = good.copy()
    indefinite[0, 0] = -0.01
    nan = np.full((6, 6), np.nan)
    assert usable_covariances(np.stack([good, asymmetric, indefinite, nan])).tolist() == [True, False, False, False]


def test_the_stated_covariance_maps_onto_the_filters_measurement() -> None:
    rng = np.random.default_rng(0)
    A = rng.standard_normal((6, 6))
    C = A @ A.T + 0.1 * np.eye(6)
    C = 0.5 * (C + C.T)  # exactly symmetric whatever the BLAS (the filter's R is the symmetrised C)
    z = np.concatenate((rng.standard_normal(4), rng.standard_normal(3)))
    z[:4] /= np.linalg.norm(z[:4])
    covariances = np.stack([C, np.full((6, 6), np.nan), C])[None]
    measurements, mask = np.tile(z, (1, 3, 1)), np.array([[True, True, False]])
    R6, defaults6 = message_noise(covariances, measurements, mask, np.eye(6))
    np.testing.assert_array_equal(R6[0, 0], C)
    np.testing.assert_array_equal(R6[0, 1], np.eye(6))  # no covariance: the default
    assert defaults6.tolist() == [1]  # (step 2 has no measurement: not counted)
    default7 = np.diag([0.01] * 4 + [0.04] * 3)
    R7, _ = message_noise(covariances, measurements, mask, default7)
    theta, q = theta_matrix(z[:4]), z[:4]
    np.testing.assert_allclose(R7[0, 0, 0:4, 0:4], 0.25 * theta @ C[:3, :3] @ theta.T + 0.01 * np.outer(q, q), atol=1e-15)
    np.testing.assert_allclose(R7[0, 0, 0:4, 4:7], 0.5 * theta @ C[:3, 3:], atol=1e-15)
    np.testing.assert_array_equal(R7[0, 0, 4:, 4:], C[3:, 3:])
    assert np.all(np.linalg.eigvalsh(R7[0, 0]) > 0)
    with pytest.raises(ValueError, match="measurement_noise must be one of"):
        KalmanEstimator(measurement_noise="sensor")


@pytest.mark.parametrize("variant", ["mekf", "ekf"])
def test_a_filter_told_the_noise_step_by_its_messages_follows_it(variant: str) -> None:
    scenario = get_scenario("spin-noise-step").replace(n_steps=600, measurement_covariance=True)
    episodes = generate_episodes(scenario, 3, split="test")
    r_std = [0.1] * 6 if variant == "mekf" else [0.05] * 4 + [0.1] * 3  # the calm noise
    plain = KalmanEstimator(variant=variant, r_std=r_std)
    told = KalmanEstimator(variant=variant, r_std=r_std, measurement_noise="message")
    assert told.to_config()["measurement_noise"] == "message" and "measurement_noise" not in plain.to_config()
    scores = {}
    for name, estimator in (("plain", plain), ("told", told)):
        kwargs = {"measurement_covariances": episodes.measurement_covariances} if name == "told" else {}
        estimates = estimator.estimate(episodes.measurements, episodes.valid, scenario.dt, **kwargs)
        scores[name] = state_rmse(component_errors(episodes.truth, estimates.means)[:, 100:]).mean()
    assert scores["told"] < 0.9 * scores["plain"]
    assert estimates.extras["measurement_noise_defaults"].tolist() == [0, 0, 0]
    without = told.estimate(episodes.measurements, episodes.valid, scenario.dt)  # no covariances: R, counted
    assert without.extras["measurement_noise_defaults"].tolist() == np.count_nonzero(episodes.valid, axis=1).tolist()
