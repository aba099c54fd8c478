"""Multiplicative extended Kalman filter for pose and twist (Markley 2003).

F. L. Markley, "Attitude error representations for Kalman filtering", JGCD 26(2), 2003; the
reset step and Jacobians follow J. Sola, "Quaternion kinematics for the error-state Kalman
filter", arXiv:1711.02508, sections 6-7, written here for a *global* (world-frame) error.

The nominal state is the usual 13-vector ``[q, r, w, v]`` with a unit quaternion; the filter's
covariance is that of the 12-dim error ``[dtheta, dr, dw, dv]`` with
``q_true = exp(dtheta / 2) (x) q``. Unlike the additive EKF, whose 4x4 attitude covariance is
rank-deficient, this covariance is full rank, and ``Q`` and ``R`` are physical: rad, m, rad/s,
m/s per step (process) and rad, m (measurement).

Predict: the model's mean and error transition ``Phi`` (:func:`fkn_bench.models.error_state.error_transition`:
the exact exponential and left Jacobian of SO(3) for the constant rate, the model's Jacobian seen
through the error for any other model; states beyond the 13, e.g. inertia ratios, are additive,
and the error state then has ``n - 1`` components), ``P' = Phi P Phi^T + Q``.
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
from fkn_bench.models.error_state import error_transition, left_jacobian
from fkn_bench.models.noise import NoiseLayout
from fkn_bench.models.pose_twist import PoseTwistModel
from fkn_bench.geometry import quaternion as qx
from fkn_bench.linalg import add_matmul, dot, eye, namespace, symmetrize, zeros
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

    def predict(self, state: FilterState, process_noise: Array, dt: float) -> FilterState:
        mean, Phi = error_transition(self.model, state.mean, dt)
        return FilterState(mean, symmetrize(add_matmul(process_noise, Phi @ state.covariance, Phi.swapaxes(1, 2))))

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
