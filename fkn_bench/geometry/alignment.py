"""Rigid alignment of two point sets: the least-squares rotation and translation (no scale).

:func:`umeyama` solves ``min_{R, t} sum_i ||y_i - (R x_i + t)||^2`` over rotations ``R``
(``det R = +1``) and translations ``t`` in closed form (Umeyama, "Least-squares estimation of
transformation parameters between two point patterns", IEEE TPAMI 13(4), 1991, Theorem without
the scale factor): with the means ``mu_x``, ``mu_y`` and the cross-covariance
``Sigma = (1/n) sum_i (y_i - mu_y)(x_i - mu_x)^T = U D V^T`` (SVD),
``R = U S V^T`` where ``S = diag(1, 1, det(U) det(V))`` (a reflection is never returned), and
``t = mu_y - R mu_x``. The solution is unique when ``rank(Sigma) >= 2`` (the points are not all on
one line); otherwise :func:`umeyama` raises.

Points on one line (a target tumbling in place, or drifting in a straight line) leave the rotation
about that line to their noise. :func:`attitude_alignment` takes the rotation from attitude pairs
instead: the chordal L2 mean of ``R_i = T_i S_i^T`` over pairs of body-to-world rotations of the
target (``T_i``) and the source (``S_i``), ``argmax_R trace(R^T sum_i T_i S_i^T)`` (Hartley,
Trumpf, Dai and Li, "Rotation averaging", IJCV 103(3), 2013), solved by the same SVD, and
``t = mu_y - R mu_x`` from the positions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fkn_bench.geometry import quaternion as quat
from fkn_bench.types import ArrayF, Float

__all__ = ["RigidTransform", "umeyama", "attitude_alignment", "matrix_to_quaternion"]


@dataclass(frozen=True, eq=False)
class RigidTransform:
    """``y = R x + t``.

    Attributes:
        rotation: ``(3, 3)`` rotation matrix ``R`` (``det R = +1``).
        translation: ``(3,)`` ``t``, in the units of the points.
        rms_residual: root mean square of ``||y_i - (R x_i + t)||`` over the fitted points.
        points: number of point pairs fitted.
        method: ``"positions"`` (:func:`umeyama`) or ``"attitudes"`` (:func:`attitude_alignment`).
    """

    rotation: Float[ArrayF, "3 3"]
    translation: Float[ArrayF, "3"]
    rms_residual: float
    points: int
    method: str = "positions"

    @property
    def quaternion(self) -> Float[ArrayF, "4"]:
        """``R`` as a unit quaternion ``[qw, qx, qy, qz]`` (Hamilton, ``qw >= 0``)."""
        return matrix_to_quaternion(self.rotation)

    @property
    def angle(self) -> float:
        """Rotation angle of ``R``, rad, in ``[0, pi]``."""
        return float(np.linalg.norm(quat.to_rotation_vector(self.quaternion)))

    def apply(self, points: Float[ArrayF, "N 3"]) -> Float[ArrayF, "N 3"]:
        """``R x + t`` for each row ``x``."""
        return np.asarray(points, dtype=np.float64) @ self.rotation.T + self.translation


def matrix_to_quaternion(rotation: Float[ArrayF, "3 3"]) -> Float[ArrayF, "4"]:
    """The unit quaternion ``[qw, qx, qy, qz]`` (``qw >= 0``) of a rotation matrix, with
    ``quat.rotation_matrix(q) == rotation``: Shepperd's method (J. Guidance and Control 1(3), 1978),
    which takes the square root of the largest of ``4 qw^2, 4 qx^2, 4 qy^2, 4 qz^2`` for accuracy."""
    m = np.asarray(rotation, dtype=np.float64)
    trace = np.trace(m)
    squares = np.array([1 + trace, 1 + 2 * m[0, 0] - trace, 1 + 2 * m[1, 1] - trace, 1 + 2 * m[2, 2] - trace])
    k = int(np.argmax(squares))
    s = np.sqrt(squares[k])  # = 2 |q_k|
    skew = np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])  # 4 qw [qx, qy, qz]
    if k == 0:
        q = np.array([s / 2, *(skew / (2 * s))])
    else:
        i = k - 1
        j, l = (i + 1) % 3, (i + 2) % 3
        q = np.empty(4)
        q[0] = skew[i] / (2 * s)
        q[1 + i] = s / 2
        q[1 + j] = (m[j, i] + m[i, j]) / (2 * s)
        q[1 + l] = (m[l, i] + m[i, l]) / (2 * s)
    q /= np.linalg.norm(q)
    return -q if q[0] < 0 else q


def umeyama(source: Float[ArrayF, "N 3"], target: Float[ArrayF, "N 3"]) -> RigidTransform:
    """The rotation and translation that carry ``source`` onto ``target`` in the least-squares
    sense (module docstring).

    Raises:
        ValueError: shapes differ or are not ``(N, 3)``, values are not finite, fewer than 3
            points, or the points are (nearly) collinear, where the rotation about their line is
            not determined.
    """
    x = np.asarray(source, dtype=np.float64)
    y = np.asarray(target, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != 3 or x.shape != y.shape:
        raise ValueError(f"source and target must both have shape (N, 3) (got {x.shape} and {y.shape})")
    if len(x) < 3:
        raise ValueError(f"a rigid alignment needs at least 3 point pairs (got {len(x)})")
    if not (np.isfinite(x).all() and np.isfinite(y).all()):
        raise ValueError("the points to align must be finite")
    mu_x, mu_y = x.mean(axis=0), y.mean(axis=0)
    sigma = (y - mu_y).T @ (x - mu_x) / len(x)
    if np.linalg.svd(sigma, compute_uv=False)[1] <= 1e-12 * max(np.abs(sigma).max(), np.finfo(float).tiny):
        raise ValueError("the points to align are (nearly) collinear: the rotation about their line is not determined")
    return _transform(_rotation(sigma), x, y, "positions")


def attitude_alignment(
    source: Float[ArrayF, "N 3"], target: Float[ArrayF, "N 3"],
    source_rotations: Float[ArrayF, "N 3 3"], target_rotations: Float[ArrayF, "N 3 3"],
) -> RigidTransform:
    """The rotation that carries the source's attitudes onto the target's (chordal L2 mean of
    ``T_i S_i^T``) and the translation ``mu_target - R mu_source`` (module docstring).

    Raises:
        ValueError: shapes that do not match ``(N, 3)`` and ``(N, 3, 3)``, no pairs, or
            non-finite values.
    """
    x = np.asarray(source, dtype=np.float64)
    y = np.asarray(target, dtype=np.float64)
    s_rot = np.asarray(source_rotations, dtype=np.float64)
    t_rot = np.asarray(target_rotations, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != 3 or x.shape != y.shape or s_rot.shape != (len(x), 3, 3) or s_rot.shape != t_rot.shape:
        raise ValueError(f"positions must be (N, 3) and rotations (N, 3, 3) (got {x.shape}, {y.shape}, {s_rot.shape}, "
                         f"{t_rot.shape})")
    if len(x) == 0:
        raise ValueError("an alignment needs at least one pair")
    if not all(np.isfinite(a).all() for a in (x, y, s_rot, t_rot)):
        raise ValueError("the poses to align must be finite")
    return _transform(_rotation(np.einsum("nij,nkj->ik", t_rot, s_rot) / len(x)), x, y, "attitudes")


def _rotation(sigma: Float[ArrayF, "3 3"]) -> Float[ArrayF, "3 3"]:
    """``argmax_R trace(R^T sigma)`` over rotations: ``U diag(1, 1, det(U) det(V)) V^T``."""
    u, _, vt = np.linalg.svd(sigma)
    return u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u) * np.linalg.det(vt)) or 1.0]) @ vt


def _transform(rotation: ArrayF, x: ArrayF, y: ArrayF, method: str) -> RigidTransform:
    translation = y.mean(axis=0) - rotation @ x.mean(axis=0)
    residual = y - (x @ rotation.T + translation)
    return RigidTransform(rotation, translation, float(np.sqrt(np.mean(np.sum(residual**2, axis=1)))), len(x), method)
