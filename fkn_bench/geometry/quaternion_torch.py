"""Quaternion algebra in torch (Hamilton, scalar first ``[w, x, y, z]``), differentiable.

The torch twin of :mod:`fkn_bench.geometry.quaternion` for the filter core; functions broadcast
over leading axes. Where a formula has a removable singularity (zero rotation), both branches
are finite so that gradients through ``torch.where`` stay finite.
"""

from __future__ import annotations

import torch
from torch import Tensor

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


def multiply(p: Tensor, q: Tensor) -> Tensor:
    """Hamilton product ``p (x) q`` of ``(..., 4)`` tensors."""
    pw, px, py, pz = p.unbind(-1)
    qw, qx, qy, qz = q.unbind(-1)
    return torch.stack(
        (
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ),
        dim=-1,
    )


def conjugate(q: Tensor) -> Tensor:
    """Conjugate ``q*``."""
    return q * q.new_tensor([1.0, -1.0, -1.0, -1.0])


def theta_matrix(q: Tensor) -> Tensor:
    """The paper's ``Theta(q)`` ``(..., 4, 3)``: ``Theta(q) w = [0, w] (x) q`` (FlexKalmanNet eq. 11)."""
    w, x, y, z = q.unbind(-1)
    return torch.stack(
        (
            torch.stack((-x, -y, -z), -1),
            torch.stack((w, z, -y), -1),
            torch.stack((-z, w, x), -1),
            torch.stack((y, -x, w), -1),
        ),
        dim=-2,
    )


def omega_matrix(w: Tensor) -> Tensor:
    """``Omega(w)`` ``(..., 4, 4)`` with ``Omega(w) q = [0, w] (x) q = Theta(q) w``."""
    wx, wy, wz = w.unbind(-1)
    zero = torch.zeros_like(wx)
    return torch.stack(
        (
            torch.stack((zero, -wx, -wy, -wz), -1),
            torch.stack((wx, zero, -wz, wy), -1),
            torch.stack((wy, wz, zero, -wx), -1),
            torch.stack((wz, -wy, wx, zero), -1),
        ),
        dim=-2,
    )


def skew(v: Tensor) -> Tensor:
    """Cross-product matrix ``[v x]`` ``(..., 3, 3)``."""
    x, y, z = v.unbind(-1)
    zero = torch.zeros_like(x)
    return torch.stack(
        (
            torch.stack((zero, -z, y), -1),
            torch.stack((z, zero, -x), -1),
            torch.stack((-y, x, zero), -1),
        ),
        dim=-2,
    )


def from_rotation_vector(rotvec: Tensor) -> Tensor:
    """``exp(rotvec / 2)`` as a unit quaternion; exact and differentiable at zero."""
    angle2 = (rotvec * rotvec).sum(-1, keepdim=True)
    small = angle2 < 1e-12
    safe2 = torch.where(small, torch.ones_like(angle2), angle2)
    angle = safe2.sqrt()
    half = 0.5 * angle
    # sin(a/2)/a; series 1/2 - a^2/48 below 1e-6 rad
    scale = torch.where(small, 0.5 - angle2 / 48.0, torch.sin(half) / angle)
    cos = torch.where(small, 1.0 - angle2 / 8.0, torch.cos(half))
    return torch.cat((cos, scale * rotvec), dim=-1)


def to_rotation_vector(q: Tensor) -> Tensor:
    """Rotation vector of the shortest rotation represented by ``q`` or ``-q`` (rad)."""
    q = torch.where(q[..., :1] < 0, -q, q)
    w = q[..., :1]
    vec = q[..., 1:]
    n2 = (vec * vec).sum(-1, keepdim=True)
    small = n2 < 1e-18
    n = torch.where(small, torch.ones_like(n2), n2).sqrt()
    scale = torch.where(small, 2.0 / w, 2.0 * torch.atan2(n, w) / n)
    return scale * vec


def rotation_matrix(q: Tensor) -> Tensor:
    """Rotation matrix ``(..., 3, 3)`` of unit quaternion ``q``."""
    w, x, y, z = q.unbind(-1)
    return torch.stack(
        (
            torch.stack((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)), -1),
            torch.stack((2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)), -1),
            torch.stack((2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)), -1),
        ),
        dim=-2,
    )


def align_sign(q: Tensor, reference: Tensor) -> Tensor:
    """``q`` or ``-q``, whichever has a non-negative dot product with ``reference``."""
    dot = (q * reference).sum(-1, keepdim=True)
    return torch.where(dot < 0, -q, q)
