"""The Rauch-Tung-Striebel smoother (fkn_bench.filters.smoother): on a linear-Gaussian model it is
the batch (information-form) posterior to rounding, it never reports more uncertainty than the
filter, segments are kept apart, and the pose composition inverts its difference."""

from __future__ import annotations

import numpy as np
import pytest

from fkn_bench.filters.smoother import pose_correct, pose_difference, rts_smooth, smooth_pose
from fkn_bench.geometry import quaternion as qx
from fkn_bench.models.error_state import error_transition
from fkn_bench.models.registry import make_model

DT = 0.5
F = np.array([[1.0, DT], [0.0, 1.0]])  # 1-D constant velocity: position, velocity
Q = np.array([[0.02, 0.01], [0.01, 0.03]])
R = 0.3
M0, P0 = np.array([1.0, -0.5]), np.diag([2.0, 0.5])


def _toy(batch: int = 3, steps: int = 20, seed: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Measurements ``(B, T)`` of the position (some missing) and the mask."""
    rng = np.random.default_rng(seed)
    x = M0 + rng.multivariate_normal(np.zeros(2), P0, size=batch)
    z = np.empty((batch, steps))
    for t in range(steps):
        if t:
            x = x @ F.T + rng.multivariate_normal(np.zeros(2), Q, size=batch)
        z[:, t] = x[:, 0] + np.sqrt(R) * rng.normal(size=batch)
    mask = rng.random((batch, steps)) < 0.7
    mask[:, 0] = True
    return z, mask


def _kalman(z: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Filtered means ``(B, T, 2)`` and covariances ``(B, T, 2, 2)`` (prior N(M0, P0) at step 0)."""
    batch, steps = z.shape
    means, covs = np.empty((batch, steps, 2)), np.empty((batch, steps, 2, 2))
    for b in range(batch):
        x, P = M0.copy(), P0.copy()
        for t in range(steps):
            if t:
                x, P = F @ x, F @ P @ F.T + Q
            if mask[b, t]:
                K = P[:, 0] / (P[0, 0] + R)
                x = x + K * (z[b, t] - x[0])
                P = P - np.outer(K, P[0])
            means[b, t], covs[b, t] = x, (P + P.T) / 2
    return means, covs


def _batch_posterior(z: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The joint Gaussian posterior of every state given every measurement, by its information
    matrix (block tridiagonal): means ``(B, T, 2)`` and marginal covariances ``(B, T, 2, 2)``."""
    batch, steps = z.shape
    Qi, P0i = np.linalg.inv(Q), np.linalg.inv(P0)
    means, covs = np.empty((batch, steps, 2)), np.empty((batch, steps, 2, 2))
    for b in range(batch):
        info, vector = np.zeros((2 * steps, 2 * steps)), np.zeros(2 * steps)
        info[:2, :2] += P0i
        vector[:2] += P0i @ M0
        for t in range(steps - 1):  # x_t+1 - F x_t ~ N(0, Q)
            A = np.zeros((2, 2 * steps))
            A[:, 2 * t : 2 * t + 2], A[:, 2 * t + 2 : 2 * t + 4] = -F, np.eye(2)
            info += A.T @ Qi @ A
        for t in np.flatnonzero(mask[b]):
            info[2 * t, 2 * t] += 1.0 / R
            vector[2 * t] += z[b, t] / R
        cov = np.linalg.inv(info)
        means[b] = (cov @ vector).reshape(steps, 2)
        covs[b] = np.array([cov[2 * t : 2 * t + 2, 2 * t : 2 * t + 2] for t in range(steps)])
    return means, covs


def _linear(x: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    assert dt == DT
    return x @ F.T, np.broadcast_to(F, (x.shape[0], 2, 2))


def test_rts_equals_the_batch_posterior_of_a_linear_gaussian_model() -> None:
    z, mask = _toy()
    filtered, filtered_covs = _kalman(z, mask)
    means, covs = rts_smooth(filtered, filtered_covs, Q, DT, transition=_linear)
    expected_means, expected_covs = _batch_posterior(z, mask)
    np.testing.assert_allclose(means, expected_means, rtol=0, atol=1e-11)
    np.testing.assert_allclose(covs, expected_covs, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(covs, np.swapaxes(covs, -1, -2))  # symmetric bit for bit
    np.testing.assert_array_equal(means[:, -1], filtered[:, -1])  # the last step is the filter's


def test_the_smoothed_covariance_is_at_most_the_filtered_one() -> None:
    z, mask = _toy(seed=9)
    filtered, filtered_covs = _kalman(z, mask)
    _, covs = rts_smooth(filtered, filtered_covs, Q, DT, transition=_linear)
    assert np.linalg.eigvalsh(filtered_covs - covs).min() > -1e-12
    assert (np.trace(covs, axis1=-2, axis2=-1)[:, :-1] < np.trace(filtered_covs, axis1=-2, axis2=-1)[:, :-1]).all()


def test_an_unlinked_step_ends_a_segment() -> None:
    z, mask = _toy(batch=2, steps=12)
    filtered, filtered_covs = _kalman(z, mask)
    linked = np.ones((2, 11), dtype=bool)
    linked[0, 5] = False  # step 6 of sequence 0 does not follow from step 5
    means, covs = rts_smooth(filtered, filtered_covs, Q, DT, transition=_linear, linked=linked)
    whole, _ = rts_smooth(filtered, filtered_covs, Q, DT, transition=_linear)
    np.testing.assert_array_equal(means[0, 5], filtered[0, 5])  # the segment's last step: filtered
    np.testing.assert_array_equal(covs[0, 5], filtered_covs[0, 5])
    tail, _ = rts_smooth(filtered[:1, 6:], filtered_covs[:1, 6:], Q, DT, transition=_linear)
    np.testing.assert_array_equal(means[0, 6:], tail[0])  # the next segment is smoothed on its own
    np.testing.assert_array_equal(means[1], whole[1])
    with pytest.raises(ValueError, match="linked must have shape"):
        rts_smooth(filtered, filtered_covs, Q, DT, transition=_linear, linked=linked[:, 1:])


def test_pose_correct_inverts_pose_difference() -> None:
    rng = np.random.default_rng(1)
    q = rng.normal(size=(5, 4))
    a = np.concatenate((q / np.linalg.norm(q, axis=1, keepdims=True), rng.normal(size=(5, 11))), axis=1)
    b = a.copy()
    b[:, 0:4] = qx.multiply(qx.from_rotation_vector(rng.normal(scale=0.5, size=(5, 3))), a[:, 0:4])
    b[:, 4:] += rng.normal(size=(5, 11))
    back = pose_correct(b, pose_difference(a, b))
    np.testing.assert_allclose(qx.align_sign(back[:, 0:4], a[:, 0:4]), a[:, 0:4], atol=1e-14)
    np.testing.assert_allclose(back[:, 4:], a[:, 4:], atol=1e-14)
    np.testing.assert_allclose(pose_difference(a, a), 0.0, atol=1e-15)


def test_smooth_pose_of_a_noise_free_track_is_the_track() -> None:
    """A filtered track that is exactly the constant-rate model's error-state prediction (zero
    process noise) is its own smoothed track: every correction is zero."""
    model = make_model("constant-velocity")
    x = np.array([[1.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 0.1, -0.2, 0.3, 0.01, 0.0, -0.02]])
    track = [x]
    for _ in range(9):
        track.append(error_transition(model, track[-1], 0.1)[0])
    means = np.stack(track, axis=1)
    covs = np.broadcast_to(np.eye(12) * 0.01, (1, 10, 12, 12)).copy()
    smoothed, smoothed_covs = smooth_pose(model, means, covs, np.eye(12) * 1e-200, 0.1)
    np.testing.assert_allclose(smoothed, means, atol=1e-14)
    assert np.isfinite(smoothed_covs).all() and (smoothed_covs == np.swapaxes(smoothed_covs, -1, -2)).all()
