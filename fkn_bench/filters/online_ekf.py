"""A lean numpy EKF for online stepping: the torch EKF's arithmetic, one sequence at a time.

Torch's per-operation overhead (several microseconds) dominates a single 13-state step, so the
online ``step()`` of the EKF estimators runs this twin of :class:`~fkn_bench.filters.ekf.
ExtendedKalmanFilter` on :class:`~fkn_bench.filters.models.PoseTwistModel`: same model, same
sign alignment, Joseph form with the merged quaternion projection, same symmetrisation. The tests
hold the two to 1e-12 over long sequences. All functions are pure: they return new arrays.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import lapack

from fkn_bench.linalg import symmetrize
from fkn_bench.types import ArrayF

__all__ = ["predict", "update", "initial_state", "sanitize_measurement", "MIN_QUATERNION_NORM"]

MIN_QUATERNION_NORM = 1e-6
"""Measured quaternions with a smaller norm are unusable (the update is skipped)."""

_EYE4 = np.eye(4)
_EYE13 = np.eye(13)


def _row_basis() -> ArrayF:
    """``B (13, 52)`` with ``x @ B = [Omega(w) | 0 | Theta(q) | 0]`` flattened (4 x 13); rows of
    ``r`` and ``v`` are zero."""
    basis = np.zeros((13, 4, 13))
    for i in range(4):
        q = np.zeros(4)
        q[i] = 1.0
        w_, x_, y_, z_ = q
        basis[i, :, 7:10] = ((-x_, -y_, -z_), (w_, z_, -y_), (-z_, w_, x_), (y_, -x_, w_))
    for i in range(3):
        w = np.zeros(3)
        w[i] = 1.0
        a, b, c = w
        basis[7 + i, :, 0:4] = ((0, -a, -b, -c), (a, 0, -c, b), (b, c, 0, -a), (c, -b, a, 0))
    return basis.reshape(13, 52)


_ROW_BASIS = _row_basis()
_TEMPLATES: dict[float, tuple[ArrayF, ArrayF]] = {}


def _template(dt: float) -> tuple[ArrayF, ArrayF]:
    """``(A, B)``: the transition with ``r += dt v`` only, and the quaternion-row basis scaled
    by ``dt / 2``, cached per step length."""
    cached = _TEMPLATES.get(dt)
    if cached is None:
        if len(_TEMPLATES) >= 16:  # bounded: irregular time steps must not grow the cache
            _TEMPLATES.clear()
        A = np.eye(13)
        A[4:7, 10:13] = dt * np.eye(3)
        cached = _TEMPLATES[dt] = (A, (0.5 * dt) * _ROW_BASIS)
    return cached


def predict(x: ArrayF, P: ArrayF, Q: ArrayF, dt: float) -> tuple[ArrayF, ArrayF]:
    """``x- = f(x)``, ``P- = F P F^T + Q`` for the paper's model (FlexKalmanNet eqs. 1-2, 8-11).

    ``F`` is ``A`` (``r += dt v``) plus ``dt/2 Omega(w)`` and ``dt/2 Theta(q)`` in its quaternion
    rows; the mean is ``A x`` plus ``dt/2 Omega(w) q`` in the quaternion. ``P-`` is symmetrised,
    as in the torch EKF.
    """
    A, basis = _template(dt)
    rows = (x @ basis).reshape(4, 13)  # [dt/2 Omega(w) | 0 | dt/2 Theta(q) | 0]
    x_pred = A @ x
    x_pred[0:4] += rows[:, 0:4] @ x[0:4]
    F = A.copy()
    F[0:4] += rows
    return x_pred, symmetrize(F @ P @ F.T + Q)


_FLIP = np.array([-1.0, -1.0, -1.0, -1.0, 1.0, 1.0, 1.0])
_GAIN_TEMPLATE = np.concatenate((np.eye(13), np.zeros((13, 7))), axis=1)  # [I | 0], 13 x 20


def update(x: ArrayF, P: ArrayF, z: ArrayF, R: ArrayF) -> tuple[ArrayF, ArrayF, ArrayF, ArrayF]:
    """Measurement update with ``z (7,)`` (usable, see :func:`sanitize_measurement`).

    The Joseph form and the quaternion projection ``T`` in one product:
    ``P+ = G blockdiag(P, R) G^T`` with ``G = T [I - K H | K]``.
    Returns ``(x+, P+, nu, S)`` with the innovation ``nu`` formed after sign alignment.
    """
    if z[0:4] @ x[0:4] < 0.0:
        z = z * _FLIP
    nu = z - x[0:7]
    S = P[0:7, 0:7] + R  # exactly symmetric: P and R are
    factor, info = lapack.dpotrf(S, lower=1, clean=0)
    if info != 0:
        raise np.linalg.LinAlgError(f"innovation covariance is not positive definite (dpotrf info {info})")
    Kt, info = lapack.dpotrs(factor, P[0:7], lower=1)  # K^T = S^-1 H P  (7 x 13)
    x_post = x + nu @ Kt
    norm = math.sqrt(x_post[0:4] @ x_post[0:4])
    unit = x_post[0:4] / norm
    x_post[0:4] = unit
    N = (_EYE4 - unit[:, None] * unit) / norm
    G = _GAIN_TEMPLATE.copy()
    G[:, 0:7] -= Kt.T
    G[:, 13:20] = Kt.T
    G[0:4] = N @ G[0:4]
    D = np.zeros((20, 20))
    D[0:13, 0:13] = P
    D[13:20, 13:20] = R
    return x_post, symmetrize(G @ D @ G.T), nu, S


def initial_state(z: ArrayF) -> ArrayF:
    """State initialised from a usable measurement: attitude and position from it, rates zero."""
    x = np.zeros(13)
    x[0:7] = z
    return x


def sanitize_measurement(z: ArrayF) -> ArrayF | None:
    """The measurement with a unit quaternion, or ``None`` when it is unusable (non-finite
    entries, or a quaternion of norm below :data:`MIN_QUATERNION_NORM` or whose norm overflows):
    the documented rule is to skip the update."""
    if not np.isfinite(z).all():
        return None
    norm = math.sqrt(z[0:4] @ z[0:4])
    if not norm >= MIN_QUATERNION_NORM or not math.isfinite(norm):  # tiny, or |q|^2 overflowed
        return None
    out = z.copy()
    out[0:4] /= norm
    return out
