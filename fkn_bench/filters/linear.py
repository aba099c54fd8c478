"""The textbook linear Kalman filter in plain numpy: the reference the filter core reduces to.

``x' = A x + w, w ~ N(0, Q)``; ``y = H x + v, v ~ N(0, R)``; predict ``x- = A x+``,
``P- = A P+ A^T + Q``; update ``K = P- H^T (H P- H^T + R)^-1``, ``x+ = x- + K (y - H x-)``,
``P+ = (I - K H) P-`` (Kalman 1960; Simon, Optimal State Estimation, 2006, eqs. 5.17-5.19).
Deliberately independent of torch and of the rest of the core: the tests check that the EKF and
the UKF on a :class:`~fkn_bench.models.linear.LinearGaussianModel` reproduce it. The covariances
it returns are symmetrised (:func:`fkn_bench.linalg.symmetrize`; the textbook ``(I - K H) P-`` is
symmetric only to rounding).
"""

from __future__ import annotations

import numpy as np

from fkn_bench.linalg import symmetrize
from fkn_bench.types import ArrayB, ArrayF

__all__ = ["linear_kalman_filter"]


def linear_kalman_filter(
    A: ArrayF,
    H: ArrayF,
    Q: ArrayF,
    R: ArrayF,
    x0: ArrayF,
    P0: ArrayF,
    measurements: ArrayF,
    mask: ArrayB,
) -> tuple[ArrayF, ArrayF]:
    """Filter one sequence ``measurements (T, m)`` with validity ``mask (T,)``.

    ``x0``, ``P0`` is the prior of step 0 (updated with measurement 0 if valid); step ``t > 0``
    predicts from ``t - 1`` first. Returns posterior means ``(T, n)`` and covariances
    ``(T, n, n)``.
    """
    x, P = np.array(x0, dtype=float), np.array(P0, dtype=float)
    steps = len(measurements)
    means = np.empty((steps, len(x)))
    covariances = np.empty((steps, len(x), len(x)))
    identity = np.eye(len(x))
    for t in range(steps):
        if t > 0:
            x = A @ x
            P = A @ P @ A.T + Q
        if mask[t]:
            S = H @ P @ H.T + R
            K = P @ H.T @ np.linalg.inv(S)
            x = x + K @ (measurements[t] - H @ x)
            P = (identity - K @ H) @ P
        P = symmetrize(P)  # once per step, before it is stored (covers predict-only steps)
        means[t], covariances[t] = x, P
    return means, covariances
