"""Quaternion algebra, Hamilton convention, scalar first ``[w, x, y, z]``, for numpy and torch.

Every function takes numpy arrays (or what ``numpy.asarray`` takes; computed in float64) or torch
tensors (differentiable; any float dtype and device) and returns the same kind; it broadcasts over
leading axes (``(..., 4)`` quaternions, ``(..., 3)`` vectors) and never mutates its inputs. ``q``
and ``-q`` are one attitude; a function whose result depends on the sign says how it picks it.

numpy evaluates each formula entry by entry, the same operations in the same order at every batch
size (the simulator's truths are made of these bits); a single row (``(1, 4)``, ``(1, 3)``, and
``(4,)`` for :func:`multiply`) runs the same operations on Python floats (numpy adds a row of 3 or
4 in order; its ``sin``, ``cos`` and ``arctan2`` are called): the same bits without numpy's
per-call cost in an online step. torch writes a map linear in ``p q^T`` or ``q q^T``
(:func:`multiply`, :func:`rotation_matrix`) as one product with a constant matrix of 0, +-1 and
+-2: fewer kernels and autograd nodes (the last bit may differ from numpy's); its ``where``
branches stay finite at removable singularities (zero rotation, a zero quaternion), so gradients
do. The ``Theta``, ``Omega`` and skew matrices and :func:`rotation_jacobian` are such products on
both.

References: J. Sola, "Quaternion kinematics for the error-state Kalman filter", arXiv:1711.02508
(2017), sections 2 and 4 (Hamilton product, exponential and logarithm maps, slerp);
K. Shoemake, "Uniform random rotations", Graphics Gems III (1992) (uniform sampling).
"""

from __future__ import annotations

import math
import sys
from typing import Any

import numpy as np

from fkn_bench.linalg import constant, namespace
from fkn_bench.types import Array, ArrayF

__all__ = [
    "IDENTITY", "multiply", "conjugate", "normalize", "canonical", "align_sign", "from_rotation_vector",
    "to_rotation_vector", "error_rotation_vector", "angle_between", "rotation_matrix", "rotate", "rotation_jacobian",
    "theta_matrix", "omega_matrix", "right_theta_matrix", "right_omega_matrix", "skew", "slerp", "random_uniform",
    "wxyz_to_xyzw", "xyzw_to_wxyz",
]

IDENTITY: ArrayF = np.array([1.0, 0.0, 0.0, 0.0])


# ---------------------------------------------------------------------------- dispatch
def _is_torch(*arrays: Any) -> bool:
    """Whether any of ``arrays`` is a torch tensor (without importing torch)."""
    for a in arrays:
        if type(a) is not np.ndarray:
            torch = sys.modules.get("torch")
            if torch is not None and isinstance(a, torch.Tensor):
                return True
    return False


def _float(a: Any) -> Array:
    """A torch tensor as it is; anything else as a float64 numpy array."""
    return a if _is_torch(a) else np.asarray(a, dtype=float)


def _sinc(x: float) -> float:
    """``numpy.sinc`` of one Python float, with numpy's operations: ``sin(pi x) / (pi x)``,
    ``pi x`` replaced by the machine epsilon at 0 (numpy's ``sin``, not ``math.sin``)."""
    y = math.pi * x
    y = y if y != 0.0 else _EPS
    return float(np.sin(y)) / y


_EPS = float(np.finfo(np.float64).eps)


# ---------------------------------------------------------------------------- constant maps (torch)
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


def _rotation(qq: np.ndarray) -> tuple[float, ...]:
    """``R - I`` from the outer product ``qq[i, j] = q_i q_j`` of a unit quaternion."""
    (ww, wx, wy, wz), (_, xx, xy, xz), (_, _, yy, yz), (_, _, _, zz) = qq
    return (
        *(-2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy)),
        *(2 * (xy + wz), -2 * (xx + zz), 2 * (yz - wx)),
        *(2 * (xz - wy), 2 * (yz + wx), -2 * (xx + yy)),
    )


_THETA, _OMEGA, _SKEW = _linear(_theta, 4), _linear(_omega, 3), _linear(_skew, 3)
_RIGHT_THETA, _RIGHT_OMEGA = _linear(_right_theta, 4), _linear(_right_omega, 3)
_HAMILTON = _linear(lambda e: _hamilton(e.reshape(4, 4)), 16)
_ROTATION = _linear(lambda e: _rotation(e.reshape(4, 4)), 16)
_CONJUGATE = np.array([1.0, -1.0, -1.0, -1.0])


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
    v = _float(v)
    out = v @ constant(v, ("quaternion", key), lambda: C)
    return out.reshape(tuple(out.shape[:-1]) + shape)


# ---------------------------------------------------------------------------- products and signs
def multiply(p: Array, q: Array, out: ArrayF | None = None, *, axis: int = -1) -> Array:
    """Hamilton product ``p (x) q`` of quaternion arrays (broadcasting).

    Args:
        p, q: quaternions with their 4 components along ``axis`` (default: last).
        out: numpy only: an array receiving the result (must not overlap ``p`` or ``q``).
        axis: numpy only: the component axis of ``p``, ``q`` and the result.
    """
    if _is_torch(p, q):
        if out is not None or axis != -1:
            raise ValueError("multiply: out= and axis= are for numpy arrays, not torch tensors")
        pq = p[..., :, None] * q[..., None, :]
        return pq.reshape(tuple(pq.shape[:-2]) + (16,)) @ constant(pq, ("quaternion", "multiply"), lambda: _HAMILTON)
    p, q = np.asarray(p, dtype=float), np.asarray(q, dtype=float)
    if out is None and axis == -1 and p.shape == q.shape and (p.shape == (1, 4) or p.shape == (4,)):  # one row: Python floats
        (pw, px, py, pz), (qw, qx, qy, qz) = p.reshape(4).tolist(), q.reshape(4).tolist()
        return np.array([
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ]).reshape(p.shape)  # fmt: skip
    pw, px, py, pz = np.moveaxis(p, axis, 0)
    qw, qx, qy, qz = np.moveaxis(q, axis, 0)
    if out is None:
        shape = list(np.broadcast_shapes(pw.shape, qw.shape))
        shape.insert(axis % (len(shape) + 1), 4)
        out = np.empty(shape)
    components = np.moveaxis(out, axis, 0)
    # index with [i, ...]: a view even for a single quaternion (plain iteration gives scalars)
    ow, ox, oy, oz = (components[i, ...] for i in range(4))
    ow[...] = pw * qw - px * qx - py * qy - pz * qz
    ox[...] = pw * qx + px * qw + py * qz - pz * qy
    oy[...] = pw * qy - px * qz + py * qw + pz * qx
    oz[...] = pw * qz + px * qy - py * qx + pz * qw
    return out


def conjugate(q: Array) -> Array:
    """Conjugate ``q*`` (the inverse of a unit quaternion): a product with ``[1, -1, -1, -1]``."""
    if _is_torch(q):
        return q * constant(q, ("quaternion", "conjugate"), lambda: _CONJUGATE)
    return np.asarray(q, dtype=float) * _CONJUGATE


def normalize(q: Array) -> Array:
    """Scale ``q`` to unit norm. Raises ``ValueError`` for a zero or non-finite quaternion."""
    q = _float(q)
    xp = namespace(q)
    norm = np.linalg.norm(q, axis=-1, keepdims=True) if xp is np else xp.linalg.vector_norm(q, dim=-1, keepdim=True)
    if not bool(xp.all(xp.isfinite(norm))) or bool(xp.any(norm < 1e-12)):
        raise ValueError("cannot normalise a quaternion with zero or non-finite norm")
    return q / norm


def canonical(q: Array) -> Array:
    """Return ``q`` or ``-q``, whichever has a non-negative scalar part."""
    q = _float(q)
    return namespace(q).where(q[..., :1] < 0.0, -q, q)


def align_sign(q: Array, reference: Array) -> Array:
    """Return ``q`` or ``-q``, whichever points the same way as ``reference`` (dot >= 0)."""
    if _is_torch(q, reference):
        import torch

        return torch.where((q * reference).sum(-1, keepdims=True) < 0, -q, q)
    q, reference = np.asarray(q, dtype=float), np.asarray(reference, dtype=float)
    if q.shape == (1, 4) and reference.shape == (1, 4):  # one row: the same sum on Python floats
        (a0, a1, a2, a3), (b0, b1, b2, b3) = q[0].tolist(), reference[0].tolist()
        return -q if a0 * b0 + a1 * b1 + a2 * b2 + a3 * b3 < 0.0 else q.copy()
    dot = np.sum(q * reference, axis=-1, keepdims=True)
    return np.where(dot < 0.0, -q, q)


# ---------------------------------------------------------------------------- rotation vectors
def from_rotation_vector(rotvec: Array) -> Array:
    """Quaternion ``exp(rotvec / 2)`` of a rotation vector (axis times angle, rad), ``(..., 3)``:
    ``[cos(a/2), sin(a/2)/a rotvec]`` with ``a = |rotvec|``.

    numpy: ``sin(a/2)/a = sinc(a / (2 pi)) / 2``, exact at zero angle. torch: the series
    ``1/2 - a^2/48`` (and ``cos(a/2) = 1 - a^2/8``) below ``a = 1e-6`` rad, differentiable at zero.
    """
    if not _is_torch(rotvec):
        rotvec = np.asarray(rotvec, dtype=float)
        if rotvec.shape == (1, 3):  # one row: the same operations on Python floats
            x, y, z = rotvec[0].tolist()
            half = 0.5 * math.sqrt(x * x + y * y + z * z)
            if half < math.inf:
                scale = 0.5 * _sinc(half / math.pi)
                return np.array([[float(np.cos(half)), scale * x, scale * y, scale * z]])
        angle = np.linalg.norm(rotvec, axis=-1, keepdims=True)
        half = 0.5 * angle
        return np.concatenate([np.cos(half), 0.5 * np.sinc(half / np.pi) * rotvec], axis=-1)
    import torch

    angle2 = (rotvec * rotvec).sum(-1, keepdims=True)
    small = angle2 < 1e-12
    angle = torch.sqrt(torch.where(small, 1.0, angle2))
    half = 0.5 * angle
    scale = torch.where(small, 0.5 - angle2 / 48.0, torch.sin(half) / angle)
    cos = torch.where(small, 1.0 - angle2 / 8.0, torch.cos(half))
    return torch.concat((cos, scale * rotvec), axis=-1)


def to_rotation_vector(q: Array) -> Array:
    """Rotation vector (rad) of the shortest rotation represented by ``q`` (``q`` or ``-q``):
    ``2 atan2(|v|, w) v / |v|`` for ``q = [w, v]`` with ``w >= 0``.

    The result has norm in ``[0, pi]`` and is the same for ``q`` and ``-q``; ``q`` need not be
    exactly unit (it is the direction that counts). Below ``|v| = 1e-9`` the series ``2/w (1 -
    |v|^2 / (3 w^2)) v`` (numpy; torch: ``2/w v``). A zero quaternion gives NaN in numpy and 0 in
    torch (a masked row of a batch: no inf, whose gradient through ``where`` is NaN).
    """
    if not _is_torch(q):
        q = np.asarray(q, dtype=float)
        if q.shape == (1, 4):  # one row: the same operations on Python floats
            w, x, y, z = q[0].tolist()
            if w < 0.0:  # canonical
                w, x, y, z = -w, -x, -y, -z
            n = math.sqrt(x * x + y * y + z * z)
            if n + w < math.inf and (n >= 1e-9 or w * w != 0.0):  # else a division by zero (numpy: inf or NaN)
                scale = 2.0 / w * (1.0 - n * n / (3.0 * (w * w))) if n < 1e-9 else 2.0 * float(np.arctan2(n, w)) / n
                return np.array([[scale * x, scale * y, scale * z]])
        q = canonical(q)
        w = q[..., :1]
        vec = q[..., 1:]
        n = np.linalg.norm(vec, axis=-1, keepdims=True)
        angle = 2.0 * np.arctan2(n, w)
        small = n < 1e-9
        safe_n = np.where(small, 1.0, n)
        safe_w = np.where(small, w, 1.0)  # w = 0 (a half-turn) must not divide by zero below
        # series of 2 atan2(n, w) / n for small n: 2/w (1 - n^2 / (3 w^2))
        scale = np.where(small, 2.0 / safe_w * (1.0 - n**2 / (3.0 * safe_w**2)), angle / safe_n)
        return scale * vec
    import torch

    q = torch.where(q[..., :1] < 0, -q, q)
    w = q[..., :1]
    vec = q[..., 1:]
    n2 = (vec * vec).sum(-1, keepdims=True)
    small = n2 < 1e-18
    n = torch.sqrt(torch.where(small, 1.0, n2))
    scale = torch.where(small, 2.0 / torch.where(w == 0, 1.0, w), 2.0 * torch.atan2(n, w) / n)
    return scale * vec


def error_rotation_vector(q_true: Array, q_est: Array) -> Array:
    """World-frame attitude error ``dtheta`` with ``q_true = exp(dtheta/2) (x) q_est`` (rad).

    Sign-safe: the same for any sign of either quaternion.
    """
    return to_rotation_vector(multiply(q_true, conjugate(q_est)))


def angle_between(q1: Array, q2: Array) -> Array:
    """Angle (rad, in ``[0, pi]``) of the rotation between two attitudes, sign-safe.

    ``2 atan2(|vec(q_e)|, |w(q_e)|)`` with ``q_e = q1^-1 (x) q2``.
    """
    qe = multiply(conjugate(q1), q2)
    if isinstance(qe, np.ndarray):
        return 2.0 * np.arctan2(np.linalg.norm(qe[..., 1:], axis=-1), np.abs(qe[..., 0]))
    import torch

    return 2.0 * torch.atan2(torch.linalg.vector_norm(qe[..., 1:], dim=-1), qe[..., 0].abs())


# ---------------------------------------------------------------------------- matrices
def rotation_matrix(q: Array) -> Array:
    """Rotation matrix ``R(q)`` ``(..., 3, 3)`` of unit quaternion ``q`` (body to world):
    ``1 - 2 (y^2 + z^2)``, ``2 (x y - w z)``, ``2 (x z + w y)``, ... (torch: ``I + C(q q^T)``; the
    products with +-2 are exact)."""
    if _is_torch(q):
        qq = q[..., :, None] * q[..., None, :]
        flat = qq.reshape(tuple(qq.shape[:-2]) + (16,)) @ constant(qq, ("quaternion", "rotation"), lambda: _ROTATION)
        return flat.reshape(tuple(flat.shape[:-1]) + (3, 3)) + constant(qq, ("eye", 3), lambda: np.eye(3))
    q = np.asarray(q, dtype=float)
    if q.shape == (1, 4):  # one row: the formula on Python floats
        w, x, y, z = q[0].tolist()
        return np.array(
            [[[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
              [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
              [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]]
        )  # fmt: skip
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                     np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                     np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], axis=-2)


def rotate(q: Array, v: Array, *, transpose: bool = False) -> Array:
    """Rotate vectors ``v (..., 3)`` by unit quaternions ``q``: ``R(q) v = q (x) [0, v] (x) q*``
    (with ``transpose``: ``R(q)^T v``, the inverse rotation), with :func:`rotation_matrix`."""
    if _is_torch(q, v):
        R = rotation_matrix(q)
        return ((R.swapaxes(-1, -2) if transpose else R) @ v[..., None])[..., 0]
    return np.einsum("...ji,...j->...i" if transpose else "...ij,...j->...i", rotation_matrix(q), np.asarray(v, dtype=float))


def rotation_jacobian(q: Array, v: Array, *, transpose: bool = False) -> Array:
    """``d(R(q) v)/dq`` ``(..., 3, 4)`` (of ``R(q)^T v`` with ``transpose``): the exact
    derivative of :func:`rotation_matrix`'s formula times ``v``, also where ``q`` is not unit."""
    q, v = _float(q), _float(v)
    vq = v[..., :, None] * q[..., None, :]
    key = ("quaternion", "rotation-derivative", transpose)
    out = vq.reshape(tuple(vq.shape[:-2]) + (12,)) @ constant(vq, key, lambda: _ROTATION_DERIVATIVE[transpose])
    return out.reshape(tuple(out.shape[:-1]) + (3, 4))


def theta_matrix(q: Array) -> Array:
    """The paper's ``Theta(q)`` (FlexKalmanNet eq. 11), ``(..., 4, 3)``.

    ``Theta(q) w = [0, w] (x) q`` for a world-frame vector ``w``; for unit ``q`` its columns are
    orthonormal and orthogonal to ``q``, and ``2 Theta(q)^T dq`` maps a small change ``dq`` to
    the world-frame rotation vector it represents.
    """
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


def skew(v: Array) -> Array:
    """Cross-product matrix ``[v x]`` ``(..., 3, 3)``: ``[v x] u = v x u``."""
    return _apply(v, "skew", _SKEW, (3, 3))


# ---------------------------------------------------------------------------- interpolation, sampling, layout
def slerp(q0: Array, q1: Array, fraction: Array | float) -> Array:
    """Spherical linear interpolation along the shortest arc (``q1`` is sign-aligned to ``q0``):
    ``exp(f log(q1 (x) q0*)) (x) q0``.

    ``fraction`` broadcasts against the leading axes; 0 gives ``q0`` and 1 gives ``q1``.
    """
    q0 = _float(q0)
    q1 = align_sign(q1, q0)
    frac = fraction if _is_torch(fraction) else np.asarray(fraction, dtype=float)
    if _is_torch(q0) and not _is_torch(frac):
        frac = sys.modules["torch"].as_tensor(frac, dtype=q0.dtype, device=q0.device)
    frac = frac[..., None]
    delta = to_rotation_vector(multiply(q1, conjugate(q0)))
    return multiply(from_rotation_vector(frac * delta), q0)


def random_uniform(rng: np.random.Generator, size: int | tuple[int, ...] = ()) -> ArrayF:
    """Uniformly distributed random unit quaternions (Shoemake 1992), canonical sign (numpy)."""
    shape = (size,) if isinstance(size, int) else tuple(size)
    u1, u2, u3 = rng.random((3, *shape))
    a, b = np.sqrt(1.0 - u1), np.sqrt(u1)
    q = np.stack([a * np.sin(2 * np.pi * u2), a * np.cos(2 * np.pi * u2), b * np.sin(2 * np.pi * u3), b * np.cos(2 * np.pi * u3)],
                 axis=-1)
    return canonical(q)


def wxyz_to_xyzw(q: Array) -> Array:
    """Reorder scalar-first quaternions to scalar-last (ROS, scipy)."""
    q = _float(q)
    return np.roll(q, -1, axis=-1) if isinstance(q, np.ndarray) else q.roll(-1, -1)


def xyzw_to_wxyz(q: Array) -> Array:
    """Reorder scalar-last quaternions (ROS, scipy) to scalar-first."""
    q = _float(q)
    return np.roll(q, 1, axis=-1) if isinstance(q, np.ndarray) else q.roll(1, -1)
