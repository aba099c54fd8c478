"""A lean numpy EKF for online stepping: the torch EKF's arithmetic, one sequence at a time.

Torch's per-operation overhead (several microseconds) dominates a single 13-state step, so the
online ``step()`` of the EKF estimators runs this twin of :class:`~fkn_bench.filters.ekf.
ExtendedKalmanFilter` on :class:`~fkn_bench.filters.models.PoseTwistModel`: same model, same
sign alignment, Joseph form with the merged quaternion projection, same symmetrisation. The tests
hold the two to 1e-12 over long sequences. All functions are pure: they return new arrays.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack

from fkn_bench.types import ArrayF

__all__ = ["predict", "update", "initial_state", "sanitize_measurement", "MIN_QUATERNION_NORM"]

MIN_QUATERNION_NORM = 1e-6
"""Measured quaternions with a smaller norm are unusable (the update is skipped)."""

_EYE4 = np.eye(4)
_EYE13 = np.eye(13)


def _row_basis() -> ArrayF:
    """``B (7, 52)`` with ``[q, w] @ B = [Omega(w) | 0 | Theta(q) | 0]`` flattened (4 x 13)."""
    basis = np.zeros((7, 4, 13))
    for i in range(4):
        q = np.zeros(4)
        q[i] = 1.0
        w_, x_, y_, z_ = q
        basis[i, :, 7:10] = ((-x_, -y_, -z_), (w_, z_, -y_), (-z_, w_, x_), (y_, -x_, w_))
    for i in range(3):
        w = np.zeros(3)
        w[i] = 1.0
        a, b, c = w
        basis[4 + i, :, 0:4] = ((0, -a, -b, -c), (a, 0, -c, b), (b, c, 0, -a), (c, -b, a, 0))
    return basis.reshape(7, 52)


_ROW_BASIS = _row_basis()
_TEMPLATES: dict[float, ArrayF] = {}


def _template(dt: float) -> ArrayF:
    F = _TEMPLATES.get(dt)
    if F is None:
        if len(_TEMPLATES) >= 16:  # bounded: irregular time steps must not grow the cache
            _TEMPLATES.clear()
        F = np.eye(13)
        F[4:7, 10:13] = dt * np.eye(3)
        _TEMPLATES[dt] = F
    return F


def predict(x: ArrayF, P: ArrayF, Q: ArrayF, dt: float) -> tuple[ArrayF, ArrayF]:
    """``x- = f(x)``, ``P- = F P F^T + Q`` for the paper's model (FlexKalmanNet eqs. 1-2, 8-11).

    ``F`` has ``I + dt/2 Omega(w)`` and ``dt/2 Theta(q)`` in its quaternion rows.
    """
    F = _template(dt).copy()
    F[0:4] += ((0.5 * dt) * np.concatenate((x[0:4], x[7:10])) @ _ROW_BASIS).reshape(4, 13)
    x_pred = x.copy()
    x_pred[0:4] = F[0:4, 0:4] @ x[0:4]
    x_pred[4:7] += dt * x[10:13]
    return x_pred, (F @ P) @ F.T + Q


def update(x: ArrayF, P: ArrayF, z: ArrayF, R: ArrayF) -> tuple[ArrayF, ArrayF, ArrayF, ArrayF]:
    """Measurement update with ``z (7,)`` (usable, see :func:`sanitize_measurement`).

    Returns ``(x+, P+, nu, S)`` with the innovation ``nu`` formed after sign alignment.
    """
    q = x[0:4]
    if z[0] * q[0] + z[1] * q[1] + z[2] * q[2] + z[3] * q[3] < 0.0:
        z = np.concatenate((-z[0:4], z[4:7]))
    nu = z - x[0:7]
    S = P[0:7, 0:7] + R
    factor, info = lapack.dpotrf(S, lower=1, clean=0)
    if info != 0:
        raise np.linalg.LinAlgError(f"innovation covariance is not positive definite (dpotrf info {info})")
    Kt, info = lapack.dpotrs(factor, P[0:7, :], lower=1)  # K^T = S^-1 H P
    K = Kt.T
    x_post = x + K @ nu
    norm = np.sqrt(x_post[0] ** 2 + x_post[1] ** 2 + x_post[2] ** 2 + x_post[3] ** 2)
    unit = x_post[0:4] / norm
    x_post[0:4] = unit
    N = (_EYE4 - unit[:, None] * unit[None, :]) / norm
    TK = K.copy()
    TK[0:4] = N @ K[0:4]
    TA = _EYE13.copy()
    TA[0:4, 0:4] = N
    TA[:, 0:7] -= TK
    P_post = (TA @ P) @ TA.T + (TK @ R) @ TK.T
    return x_post, 0.5 * (P_post + P_post.T), nu, S


def initial_state(z: ArrayF) -> ArrayF:
    """State initialised from a usable measurement: attitude and position from it, rates zero."""
    x = np.zeros(13)
    x[0:7] = z
    return x


def sanitize_measurement(z: ArrayF) -> ArrayF | None:
    """The measurement with a unit quaternion, or ``None`` when it is unusable (non-finite
    entries, or a quaternion of norm below :data:`MIN_QUATERNION_NORM` or whose norm overflows):
    the documented rule is to skip the update."""
    if not np.all(np.isfinite(z)):
        return None
    norm = np.sqrt(z[0] ** 2 + z[1] ** 2 + z[2] ** 2 + z[3] ** 2)
    if not norm >= MIN_QUATERNION_NORM or not np.isfinite(norm):  # tiny, or |q|^2 overflowed
        return None
    out = np.array(z, dtype=float)
    out[0:4] /= norm
    return out
