"""Measurement noise from the measurements themselves: each step's ``R`` from the covariance its
message states (``geometry_msgs/PoseWithCovarianceStamped``, ``nav_msgs/Odometry``, or a scenario
with ``measurement_covariance = True``).

The stated covariance ``C`` (6x6) is that of the error ``[dtheta (rad), dr (m)]`` of the measured
pose (world-frame attitude error, ``q_true = exp(dtheta / 2) (x) q_measured``; ``fkn_bench/DESIGN.md``).
A filter whose innovation is that error (the multiplicative EKF, 6-dim) takes ``R = C``. A filter
that measures the quaternion's four components additively (the EKF and UKF on the paper's model,
7-dim) takes the first-order image of ``C`` under ``dq = 1/2 Theta(q) dtheta`` at the measured unit
quaternion ``q``::

    R_qq = 1/4 Theta C_tt Theta^T + s^2 q q^T,   R_qr = 1/2 Theta C_tr,   R_rr = C_rr

where ``s^2 = q^T R0_qq q`` is the filter's own (default) measurement variance along ``q``: the stated
covariance says nothing about the quaternion's norm, and a zero variance there would make the
innovation covariance singular.

Validation, per measured step, by the recordings' rule
(:func:`fkn_bench.recordings.base.checked_covariances`): ``C`` must be finite, symmetric (to
``1e-9`` of its largest entry) and positive definite; a step whose ``C`` is missing (NaN) or fails takes the filter's
default ``R``, and the count of such steps is reported (``Estimates.extras``,
``"measurement_noise_defaults"``, per sequence).
"""

from __future__ import annotations

import numpy as np

from fkn_bench.geometry.quaternion import theta_matrix
from fkn_bench.recordings.base import checked_covariances
from fkn_bench.types import ArrayB, ArrayF, Bool, Float

__all__ = ["MEASUREMENT_NOISE_MODES", "usable_covariances", "message_noise"]

MEASUREMENT_NOISE_MODES: tuple[str, ...] = ("default", "message")
"""``measurement_noise`` of the Kalman estimators: their own ``R``, or each message's covariance."""

def usable_covariances(covariances: Float[ArrayF, "... 6 6"]) -> Bool[ArrayB, "..."]:
    """Where a stated covariance is finite, symmetric and positive definite (the recordings' rule,
    :func:`fkn_bench.recordings.base.checked_covariances`)."""
    return checked_covariances(covariances)[1]


def message_noise(
    covariances: Float[ArrayF, "B T 6 6"] | None,
    measurements: Float[ArrayF, "B T 7"],
    mask: Bool[ArrayB, "B T"],
    default: Float[ArrayF, "m m"],
) -> tuple[Float[ArrayF, "B T m m"], np.ndarray]:
    """Each step's ``R`` ``(B, T, m, m)`` (``m`` = 6 or 7, that of ``default``, the filter's own
    ``R``) from the stated ``covariances`` (module docstring), and the number of measured steps per
    sequence ``(B,)`` that took ``default`` (no usable covariance)."""
    z = np.asarray(measurements, dtype=float)
    mask = np.asarray(mask, dtype=bool)
    batch, steps = mask.shape
    m = default.shape[0]
    R = np.broadcast_to(default, (batch, steps, m, m)).copy()
    if covariances is None:
        return R, np.count_nonzero(mask, axis=1)
    C = np.asarray(covariances, dtype=float)
    if C.shape != (batch, steps, 6, 6):
        raise ValueError(f"measurement covariances must have shape {(batch, steps, 6, 6)} (got {C.shape})")
    checked, usable = checked_covariances(C)
    use = mask & usable
    if use.any():
        c = checked[use]
        if m == 6:
            R[use] = c
        elif m == 7:
            q = z[use][:, 0:4]
            q = q / np.linalg.norm(q, axis=-1, keepdims=True)
            theta = theta_matrix(q)  # (N, 4, 3)
            normal = np.einsum("ni,ij,nj->n", q, default[0:4, 0:4], q)
            block = np.zeros((len(q), 7, 7))
            block[:, 0:4, 0:4] = 0.25 * theta @ c[:, 0:3, 0:3] @ np.swapaxes(theta, 1, 2) + normal[:, None, None] * (
                q[:, :, None] * q[:, None, :])
            block[:, 0:4, 4:7] = 0.5 * theta @ c[:, 0:3, 3:6]
            block[:, 4:7, 0:4] = np.swapaxes(block[:, 0:4, 4:7], 1, 2)
            block[:, 4:7, 4:7] = c[:, 3:6, 3:6]
            R[use] = block
        else:
            raise ValueError(f"a measurement covariance maps onto a 6- or 7-dim measurement, not {m}")
    return R, np.count_nonzero(mask & ~use, axis=1)
