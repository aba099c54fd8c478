"""Estimation errors of state sequences: per component, per state group, and as the 12-dim error.

Conventions (:mod:`fkn_bench.types`): states are ``[qw qx qy qz, rx ry rz, wx wy wz, vx vy vz]``
(Hamilton quaternion body to world, SI units, angular rate in the world frame); arrays are batch
first, ``(B, T, 13)``. Errors are *estimate minus truth* for the component errors and *truth
relative to the estimate* for the 12-dim error state (``q_true = exp(dtheta / 2) (x) q_est``,
``dr = r_true - r_est`` and so on), the convention of the filters' error covariances. Signs do not
matter to any metric built on them (squares, norms and quadratic forms).

``q`` and ``-q`` are the same attitude: the estimated quaternion is sign-aligned to the truth
before component errors are taken, and attitude error angles are sign-safe
(``2 atan2(|vec(q_e)|, |w(q_e)|)``, :func:`fkn_bench.geometry.quaternion.angle_between`), so a 180-degree flip of the
quaternion *sign* reads as 0 deg.
"""

from __future__ import annotations

import numpy as np

from fkn_bench.geometry import quaternion as quat
from fkn_bench.types import ATTITUDE, OMEGA, POSITION, STATE_DIM, VELOCITY, ArrayF, Float

__all__ = [
    "GROUPS",
    "GROUP_UNITS",
    "component_errors",
    "error_state",
    "attitude_error_deg",
    "group_errors",
]

GROUPS: tuple[str, ...] = ("attitude", "position", "omega", "velocity")
"""The four state groups of the paper's figures, in state order."""

GROUP_UNITS: dict[str, str] = {"attitude": "deg", "position": "m", "omega": "rad/s", "velocity": "m/s"}
"""Units of the group error magnitudes returned by :func:`group_errors`."""


def _check_pair(truth: ArrayF, means: ArrayF) -> tuple[ArrayF, ArrayF]:
    truth = np.asarray(truth, dtype=np.float64)
    means = np.asarray(means, dtype=np.float64)
    if truth.shape != means.shape or truth.shape[-1] != STATE_DIM:
        raise ValueError(
            f"truth and estimates must both have shape (..., {STATE_DIM}) (got {truth.shape} and {means.shape})"
        )
    return truth, means


def component_errors(truth: Float[ArrayF, "... 13"], means: Float[ArrayF, "... 13"]) -> Float[ArrayF, "... 13"]:
    """Per-component errors ``estimate - truth``, ``(..., 13)``, with the estimated quaternion
    sign-aligned to the true one first (``q_est`` or ``-q_est``, whichever has a non-negative dot
    product with ``q_true``)."""
    truth, means = _check_pair(truth, means)
    errors = means - truth
    aligned = quat.align_sign(means[..., ATTITUDE], truth[..., ATTITUDE])
    errors[..., ATTITUDE] = aligned - truth[..., ATTITUDE]
    return errors


def error_state(truth: Float[ArrayF, "... 13"], means: Float[ArrayF, "... 13"]) -> Float[ArrayF, "... 12"]:
    """The 12-dim error ``[dtheta, dr, dw, dv]``, ``(..., 12)``: ``dtheta`` (rad) is the world-frame
    rotation vector with ``q_true = exp(dtheta / 2) (x) q_est``
    (:func:`fkn_bench.geometry.quaternion.error_rotation_vector`), the rest ``truth - estimate``.
    This is the error whose covariance the estimators report as ``error_covariances``."""
    truth, means = _check_pair(truth, means)
    dtheta = quat.error_rotation_vector(truth[..., ATTITUDE], means[..., ATTITUDE])
    return np.concatenate((dtheta, truth[..., 4:] - means[..., 4:]), axis=-1)


def attitude_error_deg(q_true: Float[ArrayF, "... 4"], q_est: Float[ArrayF, "... 4"]) -> Float[ArrayF, "..."]:
    """Attitude error angle in degrees, ``(...,)``, in ``[0, 180]``; sign-safe
    (``2 atan2(|vec(q_e)|, |w(q_e)|)`` with ``q_e = q_true^-1 (x) q_est``)."""
    return np.degrees(quat.angle_between(np.asarray(q_true, dtype=float), np.asarray(q_est, dtype=float)))


def group_errors(truth: Float[ArrayF, "... 13"], means: Float[ArrayF, "... 13"]) -> dict[str, Float[ArrayF, "..."]]:
    """Error magnitudes per state group, each ``(...,)`` (the state axis removed):

    * ``attitude``: attitude error angle, deg (:func:`attitude_error_deg`);
    * ``position``: Euclidean norm of the position error, m;
    * ``omega``: norm of the angular-rate error (world frame), rad/s;
    * ``velocity``: norm of the velocity error, m/s.
    """
    truth, means = _check_pair(truth, means)
    return {
        "attitude": attitude_error_deg(truth[..., ATTITUDE], means[..., ATTITUDE]),
        "position": np.linalg.norm(means[..., POSITION] - truth[..., POSITION], axis=-1),
        "omega": np.linalg.norm(means[..., OMEGA] - truth[..., OMEGA], axis=-1),
        "velocity": np.linalg.norm(means[..., VELOCITY] - truth[..., VELOCITY], axis=-1),
    }
