"""The textbook linear Kalman filter (numpy), the reference of the linear-model tests."""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_discrete_are

from fkn_bench.filters.linear import linear_kalman_filter


def test_scalar_steps_by_hand() -> None:
    # x' = x, y = x, Q = 1, R = 1, prior N(0, 1): P+_0 = 1/2, P-_1 = 3/2, P+_1 = 3/5
    A, H, Q, R = np.eye(1), np.eye(1), np.eye(1), np.eye(1)
    means, covariances = linear_kalman_filter(A, H, Q, R, np.zeros(1), np.eye(1), np.array([[2.0], [4.0], [0.0]]), np.array([True, True, False]))
    np.testing.assert_allclose(covariances[:, 0, 0], [0.5, 0.6, 1.6])
    np.testing.assert_allclose(means[:, 0], [1.0, 1.0 + 0.6 * 3.0, 2.8])  # K_1 = 3/5; predict-only at t = 2


def test_converges_to_the_riccati_solution() -> None:
    dt = 0.1
    A = np.array([[1.0, dt], [0.0, 1.0]])
    H = np.array([[1.0, 0.0]])
    Q = np.diag([1e-4, 1e-2])
    R = np.array([[0.04]])
    steps = 400
    rng = np.random.default_rng(0)
    means, covariances = linear_kalman_filter(A, H, Q, R, np.zeros(2), 10.0 * np.eye(2), rng.standard_normal((steps, 1)), np.ones(steps, bool))
    prior = solve_discrete_are(A.T, H.T, Q, R)  # steady-state predicted covariance
    posterior = prior - prior @ H.T @ np.linalg.inv(H @ prior @ H.T + R) @ H @ prior
    np.testing.assert_allclose(covariances[-1], posterior, rtol=1e-9)
    assert means.shape == (steps, 2)


def test_missing_measurements_and_inputs_untouched() -> None:
    A, H = np.array([[1.0, 1.0], [0.0, 1.0]]), np.array([[1.0, 0.0]])
    Q, R = 0.1 * np.eye(2), np.eye(1)
    x0, P0 = np.array([1.0, 0.5]), np.eye(2)
    z = np.array([[np.nan], [2.0], [np.nan]])
    mask = np.array([False, True, False])
    copies = [a.copy() for a in (x0, P0, z)]
    means, covariances = linear_kalman_filter(A, H, Q, R, x0, P0, np.nan_to_num(z), mask)
    # exact: no update at t = 0, the prior is copied (and symmetrising the symmetric P0 returns it)
    np.testing.assert_array_equal(means[0], x0)  # no update at t = 0: the prior
    np.testing.assert_array_equal(covariances[0], P0)
    x1 = A @ x0
    P1 = A @ P0 @ A.T + Q
    K = P1 @ H.T / (H @ P1 @ H.T + R)
    np.testing.assert_allclose(means[1], x1 + (K @ (np.array([2.0]) - H @ x1)))
    np.testing.assert_allclose(means[2], A @ means[1])
    np.testing.assert_allclose(covariances[2], A @ covariances[1] @ A.T + Q)
    for original, now in zip(copies, (x0, P0, z)):
        np.testing.assert_array_equal(original, now)  # exact: inputs untouched
