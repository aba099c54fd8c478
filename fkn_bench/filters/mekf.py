"""Multiplicative extended Kalman filter for pose and twist (Markley 2003).

F. L. Markley, "Attitude error representations for Kalman filtering", JGCD 26(2), 2003; the
reset step and Jacobians follow J. Sola, "Quaternion kinematics for the error-state Kalman
filter", arXiv:1711.02508, sections 6-7, written here for a *global* (world-frame) error.

The nominal state is the usual 13-vector ``[q, r, w, v]`` with a unit quaternion; the filter's
covariance is that of the 12-dim error ``[dtheta, dr, dw, dv]`` with
``q_true = exp(dtheta / 2) (x) q``. Unlike the additive EKF, whose 4x4 attitude covariance is
rank-deficient, this covariance is full rank, and ``Q`` and ``R`` are physical: rad, m, rad/s,
m/s per step (process) and rad, m (measurement).

Predict (world-frame rate ``w``, constant over a step): ``q' = exp(w dt / 2) (x) q``,
``r' = r + v dt``; error transition ``dtheta' = R(w dt) dtheta + dt J(w dt) dw``,
``dr' = dr + dt dv`` with ``J`` the left Jacobian of SO(3).
Other process models (e.g. :class:`~fkn_bench.models.rigid_body.RigidBodyModel`) are propagated
by the model itself: the mean is ``f(x)`` (renormalised) and the error transition is the model's
Jacobian ``F`` seen through the error: ``Phi = T(q') F M(q)``, with ``M`` the additive perturbation of
an error (``dq = 1/2 [0, dtheta] (x) q = 1/2 Theta(q) dtheta``, the identity elsewhere) and ``T``
the error of an additive perturbation (``dtheta = 2 Theta(q')^T dq``). States beyond the 13 (e.g.
inertia ratios) are additive, and the error state then has ``n - 1`` components.
Update with ``z = [q_z, r_z]``: ``q_z`` is sign-aligned with ``q``, the innovation is
``[log(q_z (x) q*), r_z - r]`` (6-dim, ``H = [I6 0]``), the Joseph form gives the error estimate
and covariance, and the reset ``q <- exp(dtheta / 2) (x) q`` maps the covariance with
``G = blockdiag(I + [dtheta x] / 2, I9)``.
"""

from __future__ import annotations

import math

import numpy as np

from fkn_bench.filters.base import FilterState, KalmanFilter
from fkn_bench.filters.ekf import joseph_update
from fkn_bench.models.base import StateSpaceModel
from fkn_bench.models.noise import NoiseLayout
from fkn_bench.models.pose_twist import PoseTwistModel
from fkn_bench.geometry import quaternion_xp as qx
from fkn_bench.linalg import add_matmul, broadcast, constant, dot, eye, namespace, symmetrize, zeros
from fkn_bench.types import Array, ERROR_NAMES

__all__ = ["MultiplicativeEKF", "MEKF_MANUAL_LAYOUT", "left_jacobian"]


_ERROR_UNITS = ("rad",) * 3 + ("m",) * 3 + ("rad/s",) * 3 + ("m/s",) * 3

MEKF_MANUAL_LAYOUT = NoiseLayout(
    q_labels=ERROR_NAMES,
    q_units=_ERROR_UNITS,
    # the paper's manual tuning mapped to the error state: a quaternion-component std s is an
    # attitude std of about 2 s (dtheta = 2 Theta(q)^T dq)
    q_default=(0.01,) * 3 + (1e-4,) * 3 + (0.005,) * 3 + (1e-4,) * 3,
    r_labels=ERROR_NAMES[:3] + ("rx", "ry", "rz"),
    r_units=("rad",) * 3 + ("m",) * 3,
    r_default=(0.2,) * 3 + (0.1,) * 3,
    p0_labels=ERROR_NAMES,
    p0_units=_ERROR_UNITS,
    p0_default=(0.2,) * 3 + (0.1,) * 3 + (0.2,) * 3 + (0.003,) * 3,
)
"""Components (error state), units and defaults of the multiplicative EKF."""


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


class MultiplicativeEKF(KalmanFilter):
    """Error-state (multiplicative) EKF for the pose-and-twist state (see module docstring);
    its steps run on torch tensors (batched) and numpy arrays (online) alike."""

    name = "mekf"

    def __init__(self, *, model: StateSpaceModel | None = None) -> None:
        self.model = model if model is not None else PoseTwistModel()
        if "pose-state" not in self.model.offers:
            raise ValueError(f"the multiplicative EKF needs a pose-twist state [q, r, w, v, ...] (got {type(self.model).__name__})")
        self._exact = "exact-rotation" in self.model.offers  # the constant rate: exact exponential propagation
        self.layout = MEKF_MANUAL_LAYOUT if self._exact else _error_layout(self.model.layout, self.model.state_dim - 13)

    @property
    def covariance_dim(self) -> int:
        return self.model.state_dim - 1

    @property
    def innovation_dim(self) -> int:
        return 6

    def _transition(self, x: Array, dq: Array, dt: float) -> Array:
        """The error transition ``Phi (B, 12, 12)`` over ``dt``; ``dq = exp(w dt / 2)``."""
        xp = namespace(x)
        batch = x.shape[0]
        lower = constant(x, ("mekf-lower", float(dt)), lambda: _lower_rows(float(dt)))  # rows 3-11, and zeros
        if xp is np:  # numpy (online): the two blocks written into a copy of the constant rows
            Phi = broadcast(lower, (batch, 12, 12))
            Phi[:, 0:3, 0:3], Phi[:, 0:3, 6:9] = qx.rotation_matrix(dq), dt * left_jacobian(dt * x[:, 7:10])
            return Phi
        blank = zeros(x, (batch, 3, 3))
        top = xp.concat((qx.rotation_matrix(dq), blank, dt * left_jacobian(dt * x[:, 7:10]), blank), axis=2)
        return xp.concat((top, broadcast(lower[3:], (batch, 9, 12))), axis=1)

    def predict(self, state: FilterState, process_noise: Array, dt: float) -> FilterState:
        if not self._exact:
            return self._model_predict(state, process_noise, dt)
        x, P = state.mean, state.covariance
        xp = namespace(x)
        dq = qx.from_rotation_vector(dt * x[:, 7:10])
        Phi = self._transition(x, dq, dt)
        q = qx.multiply(dq, x[:, 0:4])
        mean = xp.concat((q, x[:, 4:7] + dt * x[:, 10:13], x[:, 7:]), axis=1)
        PhiP = Phi @ P
        P_pred = add_matmul(process_noise, PhiP, Phi.swapaxes(1, 2))
        return FilterState(mean, symmetrize(P_pred))

    def _model_predict(self, state: FilterState, process_noise: Array, dt: float) -> FilterState:
        """Any other model: its mean and Jacobian, the Jacobian mapped to the error state."""
        x, P = state.mean, state.covariance
        xp = namespace(x)
        mean, F = self.model.transition(x, dt)
        q = mean[:, 0:4] / xp.sqrt((mean[:, 0:4] * mean[:, 0:4]).sum(1, keepdims=True))
        mean = xp.concat((q, mean[:, 4:]), axis=1)
        n = x.shape[1]
        eye = constant(x, ("eye", n - 4), lambda: np.eye(n - 4))
        blank = zeros(x, (x.shape[0], 4, n - 4))
        into = xp.concat((xp.concat((0.5 * qx.theta_matrix(x[:, 0:4]), blank), axis=2),  # M: error -> additive
                          broadcast(xp.concat((zeros(x, (n - 4, 3)), eye), axis=1), (x.shape[0], n - 4, n - 1))),
                         axis=1)
        out = xp.concat((xp.concat((2.0 * qx.theta_matrix(q).swapaxes(1, 2), blank[:, :3]), axis=2),  # T: additive -> error
                         broadcast(xp.concat((zeros(x, (n - 4, 4)), eye), axis=1), (x.shape[0], n - 4, n))),
                        axis=1)
        Phi = out @ F @ into
        return FilterState(mean, symmetrize(add_matmul(process_noise, Phi @ P, Phi.swapaxes(1, 2))))

    def update(self, state: FilterState, z: Array, measurement_noise: Array) -> tuple[FilterState, Array, Array]:
        x, P = state.mean, state.covariance
        xp = namespace(x)
        q = x[:, 0:4]
        z_q = qx.align_sign(z[:, 0:4], q)
        nu = xp.concat((qx.to_rotation_vector(qx.multiply(z_q, qx.conjugate(q))), z[:, 4:7] - x[:, 4:7]), axis=1)

        def reset(dx: Array) -> tuple[Array, slice, Array]:
            return dx, slice(0, 3), eye(dx, 3) + 0.5 * qx.skew(dx[:, 0:3])

        error = zeros(x, (x.shape[0], x.shape[1] - 1))
        # P_post comes back symmetrised (the reset's G P G^T is part of joseph_update's product)
        dx, P_post, S, _ = joseph_update(error, P, nu, measurement_noise, observed=slice(0, 6), normalize=reset)
        q_post = qx.multiply(qx.from_rotation_vector(dx[:, 0:3]), q)
        if xp is np and q_post.shape[0] == 1:  # one numpy row: a scalar norm
            q_post /= math.sqrt(dot(q_post[0], q_post[0]))
        else:
            q_post = q_post / xp.sqrt((q_post * q_post).sum(1, keepdims=True))
        mean = xp.concat((q_post, x[:, 4:] + dx[:, 3:]), axis=1)
        return FilterState(mean, P_post), nu, S


def _error_layout(additive: NoiseLayout, extra: int) -> NoiseLayout:
    """The error-state layout of another model: the manual tuning's, the rate's process noise from
    the model's own layout, then the model's extra additive components (e.g. inertia ratios)."""
    error, tail = MEKF_MANUAL_LAYOUT, slice(len(additive.q_default) - extra, None)
    q_default = error.q_default[:6] + additive.q_default[7:10] + error.q_default[9:]
    return NoiseLayout(
        q_labels=error.q_labels + additive.q_labels[tail], q_units=error.q_units + additive.q_units[tail],
        q_default=q_default + additive.q_default[tail], r_labels=error.r_labels, r_units=error.r_units,
        r_default=error.r_default, p0_labels=error.p0_labels + additive.p0_labels[tail],
        p0_units=error.p0_units + additive.p0_units[tail], p0_default=error.p0_default + additive.p0_default[tail],
    )


def _lower_rows(dt: float) -> np.ndarray:
    """The error transition with zeros in rows 0-2 and its rows 3-11: ``dr' = dr + dt dv``,
    ``dw' = dw``, ``dv' = dv``."""
    lower = np.eye(12)
    lower[0:3] = 0.0
    lower[3:6, 9:12] = dt * np.eye(3)
    return lower
