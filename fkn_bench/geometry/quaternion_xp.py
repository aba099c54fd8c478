"""Quaternion algebra for the filters (Hamilton, scalar first ``[w, x, y, z]``), written once for
numpy arrays and torch tensors (differentiable); functions broadcast over leading axes.

The filters' twin of :mod:`fkn_bench.geometry.quaternion`. Where a formula has a removable
singularity (zero rotation), both branches are finite so that gradients through ``where`` stay
finite.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from fkn_bench.linalg import constant, dot, namespace
from fkn_bench.types import Array

__all__ = [
    "multiply",
    "conjugate",
    "theta_matrix",
    "omega_matrix",
    "from_rotation_vector",
    "to_rotation_vector",
    "rotation_matrix",
    "right_theta_matrix",
    "right_omega_matrix",
    "rotate",
    "rotation_jacobian",
    "skew",
    "align_sign",
]



def _linear(make: Any, inputs: int) -> np.ndarray:
    """``C (inputs, outputs)``: a map linear in its input (an array of ``(..., inputs)``) written
    as one product ``v @ C`` (products with 0 and +-1 are exact: the same numbers as the formula)."""
    return np.stack([np.asarray(make(np.eye(inputs)[i])).reshape(-1) for i in range(inputs)])


def _theta(q: Array) -> tuple[tuple[Array, ...], ...]:
    w, x, y, z = (q[..., i] for i in range(4))
    return ((-x, -y, -z), (w, z, -y), (-z, w, x), (y, -x, w))


def _omega(w: Array) -> tuple[tuple[Array, ...], ...]:
    wx, wy, wz = (w[..., i] for i in range(3))
    return ((0.0, -wx, -wy, -wz), (wx, 0.0, -wz, wy), (wy, wz, 0.0, -wx), (wz, -wy, wx, 0.0))


def _right_theta(q: Array) -> tuple[tuple[Array, ...], ...]:
    w, x, y, z = (q[..., i] for i in range(4))
    return ((-x, -y, -z), (w, -z, y), (z, w, -x), (-y, x, w))


def _right_omega(w: Array) -> tuple[tuple[Array, ...], ...]:
    wx, wy, wz = (w[..., i] for i in range(3))
    return ((0.0, -wx, -wy, -wz), (wx, 0.0, wz, -wy), (wy, -wz, 0.0, wx), (wz, wy, -wx, 0.0))


def _skew(v: Array) -> tuple[tuple[Array, ...], ...]:
    x, y, z = (v[..., i] for i in range(3))
    return ((0.0, -z, y), (z, 0.0, -x), (-y, x, 0.0))


def _hamilton(pq: Array) -> tuple[Array, ...]:
    """The Hamilton product from the outer product ``pq[i, j] = p_i q_j`` (``(4, 4)``)."""
    (pw_qw, pw_qx, pw_qy, pw_qz), (px_qw, px_qx, px_qy, px_qz), (py_qw, py_qx, py_qy, py_qz), (pz_qw, pz_qx, pz_qy, pz_qz) = pq
    return (
        pw_qw - px_qx - py_qy - pz_qz,
        pw_qx + px_qw + py_qz - pz_qy,
        pw_qy - px_qz + py_qw + pz_qx,
        pw_qz + px_qy - py_qx + pz_qw,
    )


_THETA, _OMEGA, _SKEW = _linear(_theta, 4), _linear(_omega, 3), _linear(_skew, 3)
_RIGHT_THETA, _RIGHT_OMEGA = _linear(_right_theta, 4), _linear(_right_omega, 3)
_HAMILTON = _linear(lambda e: _hamilton(e.reshape(4, 4)), 16)


def _rotation(qq: np.ndarray) -> tuple[float, ...]:
    """``R - I`` from the outer product ``qq[i, j] = q_i q_j`` of a unit quaternion."""
    (ww, wx, wy, wz), (_, xx, xy, xz), (_, _, yy, yz), (_, _, _, zz) = qq
    return (
        *(-2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy)),
        *(2 * (xy + wz), -2 * (xx + zz), 2 * (yz - wx)),
        *(2 * (xz - wy), 2 * (yz + wx), -2 * (xx + yy)),
    )


_ROTATION = _linear(lambda e: _rotation(e.reshape(4, 4)), 16)


def _rotation_derivative(transpose: bool) -> np.ndarray:
    """``K (12, 12)`` with ``vec(v q^T) @ K = d(R(q) v)/dq`` (or ``R(q)^T v``) flattened ``(3, 4)``.

    ``(R - I) v`` is a quadratic form in ``q`` for each output ``i``, ``sum_ab q_a q_b C[a, b, i, j]
    v_j``, so its derivative ``d/dq_c = sum_bj (C[c, b, i, j] + C[b, c, i, j]) q_b v_j`` is
    bilinear in ``v`` and ``q``."""
    C = _ROTATION.reshape(4, 4, 3, 3)
    if transpose:
        C = C.transpose(0, 1, 3, 2)
    return (C.transpose(3, 1, 2, 0) + C.transpose(3, 0, 2, 1)).reshape(12, 12)


_ROTATION_DERIVATIVE = {False: _rotation_derivative(False), True: _rotation_derivative(True)}


def _apply(v: Array, key: str, C: np.ndarray, shape: tuple[int, ...]) -> Array:
    out = v @ constant(v, ("quaternion", key), lambda: C)
    return out.reshape(tuple(out.shape[:-1]) + shape)


def multiply(p: Array, q: Array) -> Array:
    """Hamilton product ``p (x) q`` of ``(..., 4)`` arrays."""
    pq = p[..., :, None] * q[..., None, :]
    return pq.reshape(tuple(pq.shape[:-2]) + (16,)) @ constant(pq, ("quaternion", "multiply"), lambda: _HAMILTON)


def conjugate(q: Array) -> Array:
    """Conjugate ``q*`` (a product with ``[1, -1, -1, -1]``: exact)."""
    return q * constant(q, ("quaternion", "conjugate"), lambda: np.array([1.0, -1.0, -1.0, -1.0]))


def theta_matrix(q: Array) -> Array:
    """The paper's ``Theta(q)`` ``(..., 4, 3)``: ``Theta(q) w = [0, w] (x) q`` (FlexKalmanNet eq. 11)."""
    return _apply(q, "theta", _THETA, (4, 3))


def omega_matrix(w: Array) -> Array:
    """``Omega(w)`` ``(..., 4, 4)`` with ``Omega(w) q = [0, w] (x) q = Theta(q) w``."""
    return _apply(w, "omega", _OMEGA, (4, 4))


def right_theta_matrix(q: Array) -> Array:
    """``Theta_R(q)`` ``(..., 4, 3)``: ``Theta_R(q) w = q (x) [0, w]`` (a body-frame rate)."""
    return _apply(q, "right-theta", _RIGHT_THETA, (4, 3))


def right_omega_matrix(w: Array) -> Array:
    """``Omega_R(w)`` ``(..., 4, 4)`` with ``Omega_R(w) q = q (x) [0, w] = Theta_R(q) w``."""
    return _apply(w, "right-omega", _RIGHT_OMEGA, (4, 4))


def rotate(q: Array, v: Array, *, transpose: bool = False) -> Array:
    """``R(q) v`` (``R(q)^T v`` with ``transpose``) of ``(..., 4)`` and ``(..., 3)`` arrays, with
    :func:`rotation_matrix`'s formula (``q`` unit)."""
    R = rotation_matrix(q)
    return ((R.swapaxes(-1, -2) if transpose else R) @ v[..., None])[..., 0]


def rotation_jacobian(q: Array, v: Array, *, transpose: bool = False) -> Array:
    """``d(R(q) v)/dq`` ``(..., 3, 4)`` (of ``R(q)^T v`` with ``transpose``): the exact
    derivative of :func:`rotate`'s formula, also where ``q`` is not unit."""
    vq = v[..., :, None] * q[..., None, :]
    key = ("quaternion", "rotation-derivative", transpose)
    out = vq.reshape(tuple(vq.shape[:-2]) + (12,)) @ constant(vq, key, lambda: _ROTATION_DERIVATIVE[transpose])
    return out.reshape(tuple(out.shape[:-1]) + (3, 4))


def skew(v: Array) -> Array:
    """Cross-product matrix ``[v x]`` ``(..., 3, 3)``."""
    return _apply(v, "skew", _SKEW, (3, 3))


def from_rotation_vector(rotvec: Array) -> Array:
    """``exp(rotvec / 2)`` as a unit quaternion; exact and differentiable at zero."""
    if isinstance(rotvec, np.ndarray) and rotvec.shape == (1, 3):  # one numpy row: scalar branches
        angle2 = dot(rotvec[0], rotvec[0])
        angle = math.sqrt(angle2)
        small = angle2 < 1e-12
        out = np.empty((1, 4))
        out[0, 0] = 1.0 - angle2 / 8.0 if small else math.cos(0.5 * angle)
        out[0, 1:] = (0.5 - angle2 / 48.0 if small else math.sin(0.5 * angle) / angle) * rotvec[0]
        return out
    xp = namespace(rotvec)
    angle2 = (rotvec * rotvec).sum(-1, keepdims=True)
    small = angle2 < 1e-12
    safe2 = xp.where(small, 1.0, angle2)
    angle = xp.sqrt(safe2)
    half = 0.5 * angle
    # sin(a/2)/a; series 1/2 - a^2/48 below 1e-6 rad
    scale = xp.where(small, 0.5 - angle2 / 48.0, xp.sin(half) / angle)
    cos = xp.where(small, 1.0 - angle2 / 8.0, xp.cos(half))
    return xp.concat((cos, scale * rotvec), axis=-1)


def to_rotation_vector(q: Array) -> Array:
    """Rotation vector of the shortest rotation represented by ``q`` or ``-q`` (rad)."""
    if isinstance(q, np.ndarray) and q.shape == (1, 4):  # one numpy row: scalar branches
        w, vec = float(q[0, 0]), q[0, 1:]
        if w < 0:
            w, vec = -w, -vec
        n2 = dot(vec, vec)
        n = math.sqrt(n2)
        return ((2.0 / (w or 1.0) if n2 < 1e-18 else 2.0 * math.atan2(n, w) / n) * vec)[None]  # w = 0: a zero q
    xp = namespace(q)
    q = xp.where(q[..., :1] < 0, -q, q)
    w = q[..., :1]
    vec = q[..., 1:]
    n2 = (vec * vec).sum(-1, keepdims=True)
    small = n2 < 1e-18
    n = xp.sqrt(xp.where(small, 1.0, n2))
    # w = 0 only for a zero quaternion (a masked row): no inf, whose gradient through where is NaN
    scale = xp.where(small, 2.0 / xp.where(w == 0, 1.0, w), 2.0 * xp.atan2(n, w) / n)
    return scale * vec


def rotation_matrix(q: Array) -> Array:
    """Rotation matrix ``(..., 3, 3)`` of unit quaternion ``q``: ``I + C(q q^T)`` with
    ``1 - 2 (y^2 + z^2)``, ``2 (x y - w z)``, ... (the products with +-2 are exact: the same numbers as
    the formula written entry by entry)."""
    if isinstance(q, np.ndarray) and q.shape == (1, 4):  # one numpy row: the formula on Python floats
        w, x, y, z = q[0].tolist()
        return np.array(
            [[[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
              [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
              [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]]
        )  # fmt: skip
    qq = q[..., :, None] * q[..., None, :]
    flat = qq.reshape(tuple(qq.shape[:-2]) + (16,)) @ constant(qq, ("quaternion", "rotation"), lambda: _ROTATION)
    return flat.reshape(tuple(flat.shape[:-1]) + (3, 3)) + constant(qq, ("eye", 3), lambda: np.eye(3))


def align_sign(q: Array, reference: Array) -> Array:
    """``q`` or ``-q``, whichever has a non-negative dot product with ``reference``."""
    if isinstance(q, np.ndarray) and q.shape == (1, 4):  # one numpy row: a scalar test
        return -q if dot(q[0], reference[0]) < 0 else q
    xp = namespace(q)
    inner = (q * reference).sum(-1, keepdims=True)
    return xp.where(inner < 0, -q, q)
