"""Quaternion algebra for the filters (Hamilton, scalar first ``[w, x, y, z]``), written once for
numpy arrays and torch tensors (differentiable); functions broadcast over leading axes.

The filters' twin of :mod:`fkn_bench.geometry.quaternion`. Where a formula has a removable
singularity (zero rotation), both branches are finite so that gradients through ``where`` stay
finite.
"""

from __future__ import annotations

from typing import Any

from fkn_bench.linalg import namespace

__all__ = [
    "multiply",
    "conjugate",
    "theta_matrix",
    "omega_matrix",
    "from_rotation_vector",
    "to_rotation_vector",
    "rotation_matrix",
    "skew",
    "align_sign",
]

Array = Any


def _rows(xp: Any, rows: tuple[tuple[Array, ...], ...]) -> Array:
    """A ``(..., r, c)`` matrix from ``r`` rows of ``c`` entries ``(...)``."""
    return xp.stack([xp.stack(row, axis=-1) for row in rows], axis=-2)


def multiply(p: Array, q: Array) -> Array:
    """Hamilton product ``p (x) q`` of ``(..., 4)`` arrays."""
    xp = namespace(p)
    pw, px, py, pz = (p[..., i] for i in range(4))
    qw, qx, qy, qz = (q[..., i] for i in range(4))
    return xp.stack(
        (
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ),
        axis=-1,
    )


def conjugate(q: Array) -> Array:
    """Conjugate ``q*``."""
    return namespace(q).concat((q[..., :1], -q[..., 1:]), axis=-1)


def theta_matrix(q: Array) -> Array:
    """The paper's ``Theta(q)`` ``(..., 4, 3)``: ``Theta(q) w = [0, w] (x) q`` (FlexKalmanNet eq. 11)."""
    w, x, y, z = (q[..., i] for i in range(4))
    return _rows(namespace(q), ((-x, -y, -z), (w, z, -y), (-z, w, x), (y, -x, w)))


def omega_matrix(w: Array) -> Array:
    """``Omega(w)`` ``(..., 4, 4)`` with ``Omega(w) q = [0, w] (x) q = Theta(q) w``."""
    wx, wy, wz = (w[..., i] for i in range(3))
    zero = namespace(w).zeros_like(wx)
    return _rows(namespace(w), ((zero, -wx, -wy, -wz), (wx, zero, -wz, wy), (wy, wz, zero, -wx), (wz, -wy, wx, zero)))


def skew(v: Array) -> Array:
    """Cross-product matrix ``[v x]`` ``(..., 3, 3)``."""
    x, y, z = (v[..., i] for i in range(3))
    zero = namespace(v).zeros_like(x)
    return _rows(namespace(v), ((zero, -z, y), (z, zero, -x), (-y, x, zero)))


def from_rotation_vector(rotvec: Array) -> Array:
    """``exp(rotvec / 2)`` as a unit quaternion; exact and differentiable at zero."""
    xp = namespace(rotvec)
    angle2 = xp.sum(rotvec * rotvec, axis=-1, keepdims=True)
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
    xp = namespace(q)
    q = xp.where(q[..., :1] < 0, -q, q)
    w = q[..., :1]
    vec = q[..., 1:]
    n2 = xp.sum(vec * vec, axis=-1, keepdims=True)
    small = n2 < 1e-18
    n = xp.sqrt(xp.where(small, 1.0, n2))
    scale = xp.where(small, 2.0 / w, 2.0 * xp.atan2(n, w) / n)
    return scale * vec


def rotation_matrix(q: Array) -> Array:
    """Rotation matrix ``(..., 3, 3)`` of unit quaternion ``q``."""
    w, x, y, z = (q[..., i] for i in range(4))
    return _rows(
        namespace(q),
        (
            (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
            (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
            (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)),
        ),
    )


def align_sign(q: Array, reference: Array) -> Array:
    """``q`` or ``-q``, whichever has a non-negative dot product with ``reference``."""
    xp = namespace(q)
    dot = xp.sum(q * reference, axis=-1, keepdims=True)
    return xp.where(dot < 0, -q, q)
