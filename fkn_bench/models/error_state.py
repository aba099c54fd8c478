"""The error-state view of a pose model: its transition seen through the 12-dim attitude error.

Filters that carry the covariance of the error ``[dtheta, dr, dw, dv(, extra)]`` (the
multiplicative EKF, the RTS smoother) and the posterior Cramér-Rao bound
(:mod:`fkn_bench.metrics.bound`) need the same thing from a model that offers ``"pose-state"``: the
next mean and the error transition ``Phi = d(error') / d(error)``, written here once.

Convention (``fkn_bench/DESIGN.md``): ``q_true = exp(dtheta / 2) (x) q``, a world-frame rotation
vector ``dtheta`` (rad); the other components are additive. Two cases:

* a model offering ``"exact-rotation"`` (constant world-frame rate): ``q' = exp(w dt / 2) (x) q``,
  ``r' = r + v dt``, and ``dtheta' = R(w dt) dtheta + dt J(w dt) dw``, ``dr' = dr + dt dv``, with
  ``J`` the left Jacobian of SO(3) (Sola 2017, "Quaternion kinematics for the error-state Kalman
  filter", arXiv:1711.02508, section 7);
* any other model: its mean ``f(x)`` (quaternion renormalised) and its Jacobian ``F`` seen through
  the error: ``Phi = T(q') F M(q)``, with ``M`` the additive perturbation of an error
  (``dq = 1/2 [0, dtheta] (x) q = 1/2 Theta(q) dtheta``, the identity elsewhere) and ``T`` the
  error of an additive perturbation (``dtheta = 2 Theta(q')^T dq``). States beyond the 13 (e.g.
  inertia ratios) are additive, so the error state has ``n - 1`` components.

Numpy and torch alike (:func:`fkn_bench.linalg.namespace`), ``(B, n)`` states.
"""

from __future__ import annotations

import math

import numpy as np

from fkn_bench.geometry import quaternion as qx
from fkn_bench.linalg import broadcast, constant, eye, namespace, zeros
from fkn_bench.models.base import StateSpaceModel
from fkn_bench.types import Array

__all__ = ["error_transition", "left_jacobian", "error_dim"]


def error_dim(model: StateSpaceModel) -> int:
    """Components of ``model``'s error state (its state dimension less one: the quaternion's
    four components are a three-dimensional error)."""
    return model.state_dim - 1


def left_jacobian(phi: Array) -> Array:
    """Left Jacobian of SO(3) ``(..., 3, 3)``: ``I + (1 - cos a)/a^2 [phi x] + (a - sin a)/a^3 [phi x]^2``."""
    if isinstance(phi, np.ndarray) and phi.shape == (1, 3):  # one numpy row: on Python floats, with
        x, y, z = phi[0].tolist()  # [phi x]^2 = phi phi^T - a^2 I written out
        a2 = x * x + y * y + z * z
        a = math.sqrt(a2)
        small = a2 < 1e-8
        c1 = 0.5 - a2 / 24.0 if small else (1.0 - math.cos(a)) / a2
        c2 = 1.0 / 6.0 - a2 / 120.0 if small else (a - math.sin(a)) / (a2 * a)
        xy, xz, yz = c2 * (x * y), c2 * (x * z), c2 * (y * z)
        return np.array(
            [[[1.0 - c2 * (y * y + z * z), -c1 * z + xy, c1 * y + xz],
              [c1 * z + xy, 1.0 - c2 * (x * x + z * z), -c1 * x + yz],
              [-c1 * y + xz, c1 * x + yz, 1.0 - c2 * (x * x + y * y)]]]
        )  # fmt: skip
    K = qx.skew(phi)
    xp = namespace(phi)
    a2 = (phi * phi).sum(-1, keepdims=True)[..., None]
    small = a2 < 1e-8
    safe = xp.where(small, 1.0, a2)
    a = xp.sqrt(safe)
    c1 = xp.where(small, 0.5 - a2 / 24.0, (1.0 - xp.cos(a)) / safe)
    c2 = xp.where(small, 1.0 / 6.0 - a2 / 120.0, (a - xp.sin(a)) / (safe * a))
    return eye(phi, 3) + c1 * K + c2 * (K @ K)


def _lower_rows(dt: float) -> np.ndarray:
    """The error transition with zeros in rows 0-2 and its rows 3-11: ``dr' = dr + dt dv``,
    ``dw' = dw``, ``dv' = dv``."""
    lower = np.eye(12)
    lower[0:3] = 0.0
    lower[3:6, 9:12] = dt * np.eye(3)
    return lower


def _exact_rotation(x: Array, dt: float) -> tuple[Array, Array]:
    """Mean and ``Phi (B, 12, 12)`` of the constant world-frame rate (module docstring)."""
    xp = namespace(x)
    batch = x.shape[0]
    dq = qx.from_rotation_vector(dt * x[:, 7:10])
    mean = xp.concat((qx.multiply(dq, x[:, 0:4]), x[:, 4:7] + dt * x[:, 10:13], x[:, 7:]), axis=1)
    lower = constant(x, ("mekf-lower", float(dt)), lambda: _lower_rows(float(dt)))  # rows 3-11, and zeros
    if xp is np:  # numpy (online): the two blocks written into a copy of the constant rows
        Phi = broadcast(lower, (batch, 12, 12))
        Phi[:, 0:3, 0:3], Phi[:, 0:3, 6:9] = qx.rotation_matrix(dq), dt * left_jacobian(dt * x[:, 7:10])
        return mean, Phi
    blank = zeros(x, (batch, 3, 3))
    top = xp.concat((qx.rotation_matrix(dq), blank, dt * left_jacobian(dt * x[:, 7:10]), blank), axis=2)
    return mean, xp.concat((top, broadcast(lower[3:], (batch, 9, 12))), axis=1)


def _through_error(model: StateSpaceModel, x: Array, dt: float) -> tuple[Array, Array]:
    """Mean and ``Phi = T(q') F M(q)`` of any pose model (module docstring)."""
    xp = namespace(x)
    mean, F = model.transition(x, dt)
    q = mean[:, 0:4] / xp.sqrt((mean[:, 0:4] * mean[:, 0:4]).sum(1, keepdims=True))
    mean = xp.concat((q, mean[:, 4:]), axis=1)
    n = x.shape[1]
    identity = constant(x, ("eye", n - 4), lambda: np.eye(n - 4))
    blank = zeros(x, (x.shape[0], 4, n - 4))
    into = xp.concat((xp.concat((0.5 * qx.theta_matrix(x[:, 0:4]), blank), axis=2),  # M: error -> additive
                      broadcast(xp.concat((zeros(x, (n - 4, 3)), identity), axis=1), (x.shape[0], n - 4, n - 1))),
                     axis=1)
    out = xp.concat((xp.concat((2.0 * qx.theta_matrix(q).swapaxes(1, 2), blank[:, :3]), axis=2),  # T: additive -> error
                     broadcast(xp.concat((zeros(x, (n - 4, 4)), identity), axis=1), (x.shape[0], n - 4, n))),
                    axis=1)
    return mean, out @ F @ into


def error_transition(model: StateSpaceModel, x: Array, dt: float) -> tuple[Array, Array]:
    """``(mean (B, n), Phi (B, n - 1, n - 1))``: ``model``'s next mean from states ``x (B, n)``
    (unit quaternion) over ``dt`` seconds and its error transition (module docstring). ``model``
    must offer ``"pose-state"``."""
    if "pose-state" not in model.offers:
        raise ValueError(f"the error-state transition needs a pose-twist state [q, r, w, v, ...] (got {type(model).__name__})")
    if "exact-rotation" in model.offers:
        return _exact_rotation(x, dt)
    return _through_error(model, x, dt)
