"""Quaternion algebra in numpy: Hamilton convention, scalar first ``[w, x, y, z]``.

All functions broadcast over leading axes (``(..., 4)`` quaternions, ``(..., 3)`` vectors) and
never mutate their inputs. ``q`` and ``-q`` describe the same attitude; functions whose result
depends on that choice say how they pick it.

References: J. Sola, "Quaternion kinematics for the error-state Kalman filter", arXiv:1711.02508
(2017), sections 2 and 4 (Hamilton product, exponential and logarithm maps, slerp);
K. Shoemake, "Uniform random rotations", Graphics Gems III (1992) (uniform sampling).
"""

from __future__ import annotations

import numpy as np

from fkn_bench.geometry import quaternion_xp
from fkn_bench.types import ArrayF

__all__ = [
    "IDENTITY",
    "multiply",
    "conjugate",
    "normalize",
    "from_rotation_vector",
    "to_rotation_vector",
    "to_matrix",
    "rotate",
    "align_sign",
    "canonical",
    "angle_between",
    "error_rotation_vector",
    "random_uniform",
    "slerp",
    "theta_matrix",
    "wxyz_to_xyzw",
    "xyzw_to_wxyz",
]

IDENTITY: ArrayF = np.array([1.0, 0.0, 0.0, 0.0])


def multiply(p: ArrayF, q: ArrayF, out: ArrayF | None = None, *, axis: int = -1) -> ArrayF:
    """Hamilton product ``p (x) q`` of quaternion arrays (broadcasting).

    Args:
        p, q: quaternions with their 4 components along ``axis`` (default: last).
        out: optional array receiving the result (must not overlap ``p`` or ``q``).
        axis: the component axis of ``p``, ``q`` and the result.
    """
    pw, px, py, pz = np.moveaxis(np.asarray(p, dtype=float), axis, 0)
    qw, qx, qy, qz = np.moveaxis(np.asarray(q, dtype=float), axis, 0)
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


def conjugate(q: ArrayF) -> ArrayF:
    """Conjugate ``q*`` (the inverse of a unit quaternion)."""
    return np.asarray(q, dtype=float) * np.array([1.0, -1.0, -1.0, -1.0])


def normalize(q: ArrayF) -> ArrayF:
    """Scale ``q`` to unit norm. Raises ``ValueError`` for a zero or non-finite quaternion."""
    q = np.asarray(q, dtype=float)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if not np.all(np.isfinite(norm)) or np.any(norm < 1e-12):
        raise ValueError("cannot normalise a quaternion with zero or non-finite norm")
    return q / norm


def from_rotation_vector(rotvec: ArrayF) -> ArrayF:
    """Quaternion ``exp(rotvec / 2)`` of a rotation vector (axis times angle, rad), ``(..., 3)``.

    Uses ``sin(a/2)/a = sinc(a / (2 pi)) / 2``, exact at zero angle.
    """
    rotvec = np.asarray(rotvec, dtype=float)
    angle = np.linalg.norm(rotvec, axis=-1, keepdims=True)
    half = 0.5 * angle
    return np.concatenate([np.cos(half), 0.5 * np.sinc(half / np.pi) * rotvec], axis=-1)


def to_rotation_vector(q: ArrayF) -> ArrayF:
    """Rotation vector (rad) of the shortest rotation represented by ``q`` (``q`` or ``-q``).

    The result has norm in ``[0, pi]`` and is the same for ``q`` and ``-q``; ``q`` need not be
    exactly unit (it is the direction that counts).
    """
    q = canonical(np.asarray(q, dtype=float))
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


def to_matrix(q: ArrayF) -> ArrayF:
    """Rotation matrix ``(..., 3, 3)`` of unit quaternion ``q`` (body to world)."""
    w, x, y, z = np.moveaxis(np.asarray(q, dtype=float), -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )


def rotate(q: ArrayF, v: ArrayF) -> ArrayF:
    """Rotate vectors ``v (..., 3)`` by unit quaternions ``q``: ``q (x) [0, v] (x) q*``."""
    return np.einsum("...ij,...j->...i", to_matrix(q), np.asarray(v, dtype=float))


def align_sign(q: ArrayF, reference: ArrayF) -> ArrayF:
    """Return ``q`` or ``-q``, whichever points the same way as ``reference`` (dot >= 0)."""
    q = np.asarray(q, dtype=float)
    dot = np.sum(q * np.asarray(reference, dtype=float), axis=-1, keepdims=True)
    return np.where(dot < 0.0, -q, q)


def canonical(q: ArrayF) -> ArrayF:
    """Return ``q`` or ``-q``, whichever has a non-negative scalar part."""
    q = np.asarray(q, dtype=float)
    return np.where(q[..., :1] < 0.0, -q, q)


def error_rotation_vector(q_true: ArrayF, q_est: ArrayF) -> ArrayF:
    """World-frame attitude error ``dtheta`` with ``q_true = exp(dtheta/2) (x) q_est`` (rad).

    Sign-safe: the same for any sign of either quaternion.
    """
    return to_rotation_vector(multiply(q_true, conjugate(q_est)))


def angle_between(q1: ArrayF, q2: ArrayF) -> ArrayF:
    """Angle (rad, in ``[0, pi]``) of the rotation between two attitudes, sign-safe.

    ``2 atan2(|vec(q_e)|, |w(q_e)|)`` with ``q_e = q1^-1 (x) q2``.
    """
    qe = multiply(conjugate(q1), q2)
    return 2.0 * np.arctan2(np.linalg.norm(qe[..., 1:], axis=-1), np.abs(qe[..., 0]))


def random_uniform(rng: np.random.Generator, size: int | tuple[int, ...] = ()) -> ArrayF:
    """Uniformly distributed random unit quaternions (Shoemake 1992), canonical sign."""
    shape = (size,) if isinstance(size, int) else tuple(size)
    u1, u2, u3 = rng.random((3, *shape))
    a, b = np.sqrt(1.0 - u1), np.sqrt(u1)
    q = np.stack(
        [
            a * np.sin(2 * np.pi * u2),
            a * np.cos(2 * np.pi * u2),
            b * np.sin(2 * np.pi * u3),
            b * np.cos(2 * np.pi * u3),
        ],
        axis=-1,
    )
    return canonical(q)


def slerp(q0: ArrayF, q1: ArrayF, fraction: ArrayF | float) -> ArrayF:
    """Spherical linear interpolation along the shortest arc (``q1`` is sign-aligned to ``q0``).

    ``fraction`` broadcasts against the leading axes; 0 gives ``q0`` and 1 gives ``q1``.
    """
    q0 = np.asarray(q0, dtype=float)
    q1 = align_sign(q1, q0)
    frac = np.asarray(fraction, dtype=float)[..., None]
    delta = to_rotation_vector(multiply(q1, conjugate(q0)))
    return multiply(from_rotation_vector(frac * delta), q0)


def theta_matrix(q: ArrayF) -> ArrayF:
    """The paper's ``Theta(q)`` (FlexKalmanNet eq. 11), ``(..., 4, 3)``.

    ``Theta(q) w = [0, w] (x) q`` for a world-frame vector ``w``; for unit ``q`` its columns are
    orthonormal and orthogonal to ``q``, and ``2 Theta(q)^T dq`` maps a small change ``dq`` to
    the world-frame rotation vector it represents.
    """
    return quaternion_xp.theta_matrix(np.asarray(q, dtype=float))  # one definition, exact


def wxyz_to_xyzw(q: ArrayF) -> ArrayF:
    """Reorder scalar-first quaternions to scalar-last (ROS, scipy)."""
    return np.roll(np.asarray(q, dtype=float), -1, axis=-1)


def xyzw_to_wxyz(q: ArrayF) -> ArrayF:
    """Reorder scalar-last quaternions (ROS, scipy) to scalar-first."""
    return np.roll(np.asarray(q, dtype=float), 1, axis=-1)
