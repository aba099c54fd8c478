"""Conversions between the additive 13-dim state covariance and the 12-dim error covariance,
and from 7-dim quaternion-and-position innovations to 6-dim pose innovations (numpy).

For a unit quaternion ``q``, a small change ``dq`` is the world-frame rotation
``dtheta = 2 Theta(q)^T dq`` and conversely ``dq = Theta(q) dtheta / 2`` (``Theta`` is the paper's
eq. 11; the quaternion block maps with ``J = 2 Xi(q)^T``, Markley & Crassidis 2014, ch. 2). The additive EKF's 13x13
covariance is singular along ``q``; the 12x12 error covariance is what consistency (NEES) uses.
The congruences ``T P T^T`` are symmetric only to rounding: every covariance returned here is
symmetrised (:func:`fkn_bench.linalg.symmetrize`).
"""

from __future__ import annotations

import numpy as np

from fkn_bench.geometry.quaternion import theta_matrix
from fkn_bench.linalg import symmetrize
from fkn_bench.types import ArrayF

__all__ = ["error_covariance_from_state", "state_covariance_from_error", "pose_innovation", "with_unit_quaternion"]


def error_covariance_from_state(q: ArrayF, covariance: ArrayF) -> ArrayF:
    """12x12 error covariance ``T P T^T`` of a 13x13 state covariance ``P`` at attitude ``q``, with
    ``T = blockdiag(A, I9)`` and ``A = 2 Theta(q)^T`` (3x4), computed by blocks:
    ``[[A P_qq A^T, A P_qx], [P_xq A^T, P_xx]]`` (``x`` the nine components after ``q``)."""
    A = 2.0 * np.swapaxes(theta_matrix(q), -1, -2)
    At = np.swapaxes(A, -1, -2)
    out = np.empty(covariance.shape[:-2] + (12, 12))
    out[..., 0:3, 0:3] = A @ covariance[..., 0:4, 0:4] @ At
    out[..., 0:3, 3:12] = A @ covariance[..., 0:4, 4:13]
    out[..., 3:12, 0:3] = covariance[..., 4:13, 0:4] @ At
    out[..., 3:12, 3:12] = covariance[..., 4:13, 4:13]
    return symmetrize(out)


def state_covariance_from_error(q: ArrayF, error_covariance: ArrayF) -> ArrayF:
    """13x13 state covariance ``J P J^T`` with ``J = blockdiag(Theta(q) / 2, I9)``."""
    J = np.zeros(q.shape[:-1] + (13, 12))
    J[..., 0:4, 0:3] = 0.5 * theta_matrix(q)
    J[..., 4:13, 3:12] = np.eye(9)
    return symmetrize(J @ error_covariance @ np.swapaxes(J, -1, -2))


def pose_innovation(q_prior: ArrayF, innovation: ArrayF, covariance: ArrayF) -> tuple[ArrayF, ArrayF]:
    """6-dim pose innovation ``[dtheta, dr]`` and covariance from a 7-dim ``[dq, dr]`` one,
    linearised at the predicted attitude ``q_prior``."""
    T = np.zeros(q_prior.shape[:-1] + (6, 7))
    T[..., 0:3, 0:4] = 2.0 * np.swapaxes(theta_matrix(q_prior), -1, -2)
    T[..., 3:6, 4:7] = np.eye(3)
    nu = np.einsum("...ij,...j->...i", T, innovation)
    return nu, symmetrize(T @ covariance @ np.swapaxes(T, -1, -2))


def with_unit_quaternion(states: ArrayF) -> ArrayF:
    """``(..., 13)`` states with the quaternion scaled to unit norm (a copy).

    The additive EKF renormalises its quaternion after each update only; over prediction-only
    steps it drifts from unit norm by ``O((w dt)^2)`` per step (2.6e-5 over 9 steps on ds1).
    Estimators report unit quaternions; the filter's internal state is left as the model has it.
    A quaternion whose norm is zero or overflows (a diverged state) comes back NaN, so that the
    estimators' restart rule (:func:`fkn_bench.estimators.base.restart_diverged`) sees it.
    """
    out = np.array(states, dtype=float)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        norm = np.linalg.norm(out[..., 0:4], axis=-1, keepdims=True)
        out[..., 0:4] /= np.where((norm > 0) & (norm < np.inf), norm, np.nan)
    return out
