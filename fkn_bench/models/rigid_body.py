"""Torque-free rigid-body process model: Euler's equations and quaternion kinematics.

The state is the paper's ``[q(4), r(3), w(3), v(3)]`` (Hamilton ``wxyz``, ``q`` rotating body to
world, world-frame angular rate ``w`` in rad/s), optionally followed by two log inertia ratios
``k = [ln(Jx/Jy), ln(Jy/Jz)]`` estimated online. Over a step ``dt`` the attitude and the body rate
``w_b = R(q)^T w`` follow

    q' = 1/2 q (x) [0, w_b],    J w_b' = -w_b x (J w_b)    (Euler's equations, torque free)

integrated by the classical fourth-order Runge-Kutta method (``substeps`` steps per ``dt``); the
rate is mapped back to the world frame at the end, and ``r' = r + v dt``, ``v' = v``, ``k' = k``.
Euler's equations, componentwise ``dw_x = p_x w_y w_z`` and cyclic with
``p_x = (J_y - J_z) / J_x``, ``p_y = (J_z - J_x) / J_y``, ``p_z = (J_x - J_y) / J_z``, depend only
on the ratios of the moments (scaling ``J`` changes nothing), so only two numbers are
observable; the three ``p`` are tied by ``p_x + p_y + p_z + p_x p_y p_z = 0`` (Aghili & Parsa,
"Motion and parameter estimation of space objects using laser-vision data", JGCD 32(2), 2009;
Tweddle, Saenz-Otero, Leonard & Miller, "Factor graph modeling of rigid-body dynamics for
localization, mapping, and parameter estimation of a spinning object in space", J. Field
Robotics 32(6), 2015, who estimate the same ratios on SPHERES).

Parametrisation of the unknown inertia (Tweddle et al. 2015): ``k = [ln(Jx/Jy), ln(Jy/Jz)]``,
so ``J ~ (e^(k1+k2), e^k2, 1)``. Any real ``k`` is a positive inertia, the constraint above holds
by construction, and ``k = 0`` is the isotropic body, for which the model is the constant-rate
motion of the paper: the prior (mean 0, standard deviation ``0.3`` in
:data:`RIGID_BODY_RATIO_LAYOUT`, i.e. ratios within about 0.55-1.8 at two sigma) starts from the
paper's assumption and lets the data move away from it.

The Jacobian ``F = df/dx`` is analytic: the tangent of every Runge-Kutta stage is propagated with
the Jacobian of the continuous dynamics (``d(q (x) [0, w])/dq = Omega_R(w)``,
``d/dw = Theta_R(q)``, ``d dw/dw`` bilinear in ``p`` and ``w``), so ``F`` is the exact derivative
of the discrete map (the tests hold it to autograd). The batched operations are written once for
numpy arrays and torch tensors (differentiable); float64 numpy input (the online filters, and
tensors nobody differentiates) runs the same equations compiled, row by row, in
:mod:`fkn_bench.models.rigid_body_kernels` (equal to rounding), which also holds the propagation
the truth simulator calls (:class:`fkn_bench.envs.dynamics.FreeTumble`), with the same
coefficients (:func:`euler_coefficients`) and the same derivative.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from fkn_bench.geometry import quaternion as qx
from fkn_bench.linalg import constant, eye, namespace, zeros
from fkn_bench.models.base import prior_array
from fkn_bench.types import Array
from fkn_bench.models.noise import NoiseLayout
from fkn_bench.models.pose_twist import PAPER_MANUAL_LAYOUT, PoseTwistModel

__all__ = ["RigidBodyModel", "RIGID_BODY_LAYOUT", "RIGID_BODY_RATIO_LAYOUT", "inertia_ratios", "moments_from_ratios", "euler_coefficients"]


MAX_SUBSTEPS = 64
"""The most Runge-Kutta steps a prediction interval is refined to (see ``_stable_substeps``)."""

RIGID_BODY_LAYOUT = dataclasses.replace(
    PAPER_MANUAL_LAYOUT,
    # the paper's manual tuning, but the rate's random walk a tenth of it (5e-4 rad/s per step):
    # the model predicts how a free tumble's rate changes, so the walk only has to cover what it
    # does not know (torques, an inertia error, the rates of a forced rotation)
    q_default=(0.005,) * 4 + (1e-4,) * 3 + (5e-4,) * 3 + (1e-4,) * 3,
)
"""Components and default standard deviations of the rigid-body model with known inertia."""

RIGID_BODY_RATIO_LAYOUT = NoiseLayout(
    q_labels=PAPER_MANUAL_LAYOUT.q_labels + ("k1", "k2"),
    q_units=PAPER_MANUAL_LAYOUT.q_units + ("1", "1"),
    # the ratios are constant; a small random walk keeps their covariance from collapsing
    q_default=RIGID_BODY_LAYOUT.q_default + (1e-5, 1e-5),
    r_labels=PAPER_MANUAL_LAYOUT.r_labels,
    r_units=PAPER_MANUAL_LAYOUT.r_units,
    r_default=PAPER_MANUAL_LAYOUT.r_default,
    p0_labels=PAPER_MANUAL_LAYOUT.p0_labels + ("k1", "k2"),
    p0_units=PAPER_MANUAL_LAYOUT.p0_units + ("1", "1"),
    p0_default=PAPER_MANUAL_LAYOUT.p0_default + (0.3, 0.3),
)
"""Layout of the model with estimated inertia ratios: the paper's 13 components and the two log
ratios ``k1 = ln(Jx/Jy)``, ``k2 = ln(Jy/Jz)`` (prior standard deviation 0.3)."""


def inertia_ratios(inertia: Sequence[float]) -> tuple[float, float]:
    """``k = (ln(Jx/Jy), ln(Jy/Jz))`` of principal moments ``(Jx, Jy, Jz)``."""
    jx, jy, jz = _moments(inertia)
    return math.log(jx / jy), math.log(jy / jz)


def moments_from_ratios(k: Array) -> Array:
    """Principal moments ``(..., 3)`` normalised to ``Jz = 1`` from log ratios ``k (..., 2)``."""
    xp = namespace(k)
    k1, k2 = k[..., 0:1], k[..., 1:2]
    return xp.concat((xp.exp(k1 + k2), xp.exp(k2), xp.ones_like(k1)), axis=-1)


def euler_coefficients(inertia: Sequence[float]) -> tuple[float, float, float]:
    """``p = ((Jy - Jz)/Jx, (Jz - Jx)/Jy, (Jx - Jy)/Jz)``: ``dw_x/dt = p_x w_y w_z`` and cyclic."""
    jx, jy, jz = _moments(inertia)
    return (jy - jz) / jx, (jz - jx) / jy, (jx - jy) / jz


def _moments(inertia: Sequence[float]) -> tuple[float, float, float]:
    values = tuple(float(v) for v in inertia)
    if len(values) != 3 or not all(math.isfinite(v) and v > 0 for v in values):
        raise ValueError(f"inertia must be three finite positive principal moments (got {inertia!r})")
    return values  # type: ignore[return-value]


def _coefficients_and_derivative(k: Array) -> tuple[Array, Array]:
    """``p (B, 3)`` and ``dp/dk (B, 3, 2)`` for log ratios ``k (B, 2)``:
    ``p_x = e^-k1 - e^-(k1+k2)``, ``p_y = e^-k2 - e^k1``, ``p_z = e^(k1+k2) - e^k2``."""
    xp = namespace(k)
    k1, k2 = k[:, 0:1], k[:, 1:2]
    a, b, ab = xp.exp(k1), xp.exp(k2), xp.exp(k1 + k2)
    ia, ib, iab = 1.0 / a, 1.0 / b, 1.0 / ab
    p = xp.concat((ia - iab, ib - a, ab - b), axis=1)
    dp = xp.reshape(xp.concat((iab - ia, iab, -a, -ib, ab, ab - b), axis=1), (k.shape[0], 3, 2))
    # a physical body has |p_i| <= 1 (the triangle inequality of its moments, J_y <= J_x + J_z
    # and cyclic); k outside that region (which the filter's correction can reach) is evaluated
    # at the boundary, p clipped to [-1, 1] with zero derivative there, so that an estimate of a
    # non-physical inertia cannot make Euler's equations, and the Runge-Kutta step, blow up
    inside = xp.abs(p) <= 1.0
    if bool(inside.all()):
        return p, dp
    return xp.clip(p, -1.0, 1.0), xp.where(inside[:, :, None], dp, 0.0 * dp)


_CYCLIC = ([1, 2, 0], [2, 0, 1])

_NO_COEFFICIENTS = np.zeros(3)
"""The compiled transition's ``p_known`` argument of a model with estimated ratios (unused)."""


def _rates_matrix() -> np.ndarray:
    """``C (3, 9)``: ``w @ C`` is ``[[0, wz, wy], [wz, 0, wx], [wy, wx, 0]]`` flattened
    (``d(w_y w_z, w_z w_x, w_x w_y)/dw``)."""
    C = np.zeros((3, 3, 3))
    for i, (j, k) in enumerate(zip(*_CYCLIC)):
        C[k, i, j] = C[j, i, k] = 1.0
    return C.reshape(3, 9)


class RigidBodyModel(PoseTwistModel):
    """Torque-free rigid body (see module docstring), measured like the paper's model (``[q, r]``).

    Keyword-only arguments:
        inertia: principal moments ``(Jx, Jy, Jz)`` (kg m^2, any common scale) of the body axes
            of ``q``; with ``estimate_ratios`` the prior mean of the log ratios instead (default:
            isotropic, ``k = 0``).
        estimate_ratios: augment the state with ``k = [ln(Jx/Jy), ln(Jy/Jz)]`` (15 states).
        substeps: Runge-Kutta steps per prediction interval.
        min_quaternion_norm, max_abs_position: see :class:`~fkn_bench.models.pose_twist.PoseTwistModel`.
    """

    offers = frozenset({"pose-state"})  # (its transition is not the structured step's)

    def __init__(
        self,
        *,
        inertia: Sequence[float] | None = None,
        estimate_ratios: bool = False,
        substeps: int = 1,
        min_quaternion_norm: float = 1e-6,
        max_abs_position: float = 1e9,
    ) -> None:
        super().__init__(min_quaternion_norm=min_quaternion_norm, max_abs_position=max_abs_position)
        if isinstance(substeps, bool) or not isinstance(substeps, int) or substeps < 1:
            raise ValueError(f"substeps must be an integer >= 1 (got {substeps!r})")
        self.substeps = substeps
        self.estimate_ratios = bool(estimate_ratios)
        self.inertia = None if inertia is None else _moments(inertia)
        if self.inertia is None and not self.estimate_ratios:
            raise ValueError("a known-inertia rigid-body model needs the principal moments (inertia=...)")
        self.ratio_prior = (0.0, 0.0) if self.inertia is None else inertia_ratios(self.inertia)
        self.state_dim = 15 if self.estimate_ratios else 13
        self.layout = RIGID_BODY_RATIO_LAYOUT if self.estimate_ratios else RIGID_BODY_LAYOUT
        self.H = np.eye(7, self.state_dim)

    def predict(self, x: Array, dt: float) -> Array:
        return self.transition(x, dt, jacobian=False)[0]

    def transition(self, x: Array, dt: float, *, jacobian: bool = True) -> tuple[Array, Array]:
        """``(f(x) (B, n), F = df/dx (B, n, n) or None)`` of states ``x (B, n)`` over ``dt``
        seconds. A float64 numpy batch takes the compiled kernel
        (:func:`fkn_bench.models.rigid_body_kernels.transition`, row by row); a CPU tensor
        nobody differentiates (the batched filters at evaluation) takes the numpy path on a view
        of it; anything else (a tensor under autograd, a GPU, another dtype) the batched
        operations of ``_transition``. The paths agree to rounding."""
        if not isinstance(x, np.ndarray):
            import torch

            if x.device.type == "cpu" and not (x.requires_grad and torch.is_grad_enabled()):
                mean, F = self.transition(x.detach().numpy(), dt, jacobian=jacobian)
                return torch.from_numpy(mean), None if F is None else torch.from_numpy(F)
            return self._transition(x, dt, jacobian=jacobian)
        if x.dtype != np.float64 or x.ndim != 2 or x.shape[1] != self.state_dim:
            return self._transition(x, dt, jacobian=jacobian)
        return self._compiled_transition(x, dt, jacobian=bool(jacobian))

    def _compiled_transition(self, x: np.ndarray, dt: float, *, jacobian: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """``_transition`` of a float64 batch ``x (B, n)`` in one compiled call."""
        from fkn_bench.models import rigid_body_kernels  # (numba, imported where first used)

        batch, n = x.shape
        if self.estimate_ratios:
            p = _NO_COEFFICIENTS  # (the kernel takes p from the ratios in the state)
        else:
            p = constant(x, ("euler", self.inertia), lambda: np.array([euler_coefficients(self.inertia)]), self._constants())[0]
        mean, F = np.empty((batch, n)), np.empty((batch, n, n) if jacobian else (0, n, n))
        rigid_body_kernels.transition(np.ascontiguousarray(x), p, float(dt), self.substeps, MAX_SUBSTEPS, jacobian, mean, F)
        return mean, F if jacobian else None

    def _transition(self, x: Array, dt: float, *, jacobian: bool) -> tuple[Array, Array | None]:
        xp = namespace(x)
        batch, dt = x.shape[0], float(dt)
        q, w = x[:, 0:4], x[:, 7:10]
        if self.estimate_ratios:
            p, dp = _coefficients_and_derivative(x[:, 13:15])
        else:
            p, dp = constant(x, ("euler", self.inertia), lambda: np.array([euler_coefficients(self.inertia)]), self._constants()), None
        y = xp.concat((q, qx.rotate(_unit(q), w, transpose=True)), axis=1)  # (q, w_b)
        tangent = None
        if jacobian:  # d y / d(y0, k): the identity, then zeros for the ratios
            tangent = constant(x, ("rk4-start", self.state_dim), lambda: np.eye(7, 7 + self.state_dim - 13), self._constants())
            tangent = xp.broadcast_to(tangent, (batch,) + tuple(tangent.shape))
        y, tangent = self._integrate(y, tangent, p, dp, dt)
        q1, wb1 = y[:, 0:4], y[:, 4:7]
        w1 = qx.rotate(_unit(q1), wb1)
        mean = xp.concat((q1, x[:, 4:7] + dt * x[:, 10:13], w1, x[:, 10:]), axis=1)
        if not jacobian:
            return mean, None
        return mean, self._jacobian(x, q1, wb1, tangent, dt)

    def _integrate(self, y: Array, tangent: Array | None, p: Array, dp: Array | None, dt: float) -> tuple[Array, Array | None]:
        """``y = (q, w_b)`` and its tangent after ``dt`` by classical Runge-Kutta steps.

        ``substeps`` steps per ``dt``, or more for rows whose body rate is so fast that one
        step would leave RK4's stability region: the linearised dynamics have eigenvalues of
        magnitude at most ``|w| (1/2 + max|p|)`` (the quaternion kinematics ``|w| / 2``, Euler's
        equations ``|p| |w|``) and RK4 is stable for ``h |lambda|`` up to about 2.8 on the
        imaginary axis, so such a row's step is refined until ``h |w| (1/2 + max|p|) <= 1/4``
        (well inside that region: a rotation of 3 rad in 6 steps is then 5e-5 off). At the rates
        of a real tumble (``|w| dt`` under 1/6, i.e. 1.7 rad/s at ``dt = 0.1``) no row is; a wild estimate (a filter
        corrected by gross outliers to tens of rad/s) gets the steps it needs, up to
        :data:`MAX_SUBSTEPS` (hundreds of rad/s at ``dt = 0.1``; beyond, the estimators' restart
        rule takes over: :func:`fkn_bench.estimators.base.restart_diverged`), instead of an
        exponential blow-up. The refined rows are integrated on their own, so the other rows'
        results do not depend on them."""
        xp = namespace(y)
        rate = xp.sqrt((y[:, 4:7] * y[:, 4:7]).sum(-1)) * (0.5 + xp.amax(xp.abs(p), -1))
        if xp is not np:
            rate = rate.detach().cpu().numpy()
        needed = (4.0 * dt) * rate  # RK4 steps each row needs (NaN compares False: nothing to refine)
        wild = needed > self.substeps
        if not wild.any():
            return self._rk4(y, tangent, p, dp, dt, self.substeps)
        tame_rows, wild_rows = np.flatnonzero(~wild), np.flatnonzero(wild)
        steps = int(min(math.ceil(min(float(needed[wild].max()), MAX_SUBSTEPS)), MAX_SUBSTEPS))
        pick = (lambda a, rows: a if a is None or a.shape[0] == 1 else a[rows]) if xp is np else (
            lambda a, rows: a if a is None or a.shape[0] == 1 else a[xp.from_numpy(rows).to(a.device)])
        parts = [self._rk4(pick(y, rows), pick(tangent, rows), pick(p, rows), pick(dp, rows), dt, n)
                 for rows, n in ((tame_rows, self.substeps), (wild_rows, steps)) if rows.size]
        order = np.argsort(np.concatenate((tame_rows, wild_rows)))
        index = order if xp is np else xp.from_numpy(order).to(y.device)
        y = xp.concat([part[0] for part in parts], axis=0)[index]
        if tangent is not None:
            tangent = xp.concat([part[1] for part in parts], axis=0)[index]
        return y, tangent

    def _rk4(self, y: Array, tangent: Array | None, p: Array, dp: Array | None, dt: float, substeps: int) -> tuple[Array, Array | None]:
        h = dt / substeps
        for _ in range(substeps):
            y, tangent = self._rk4_step(y, tangent, p, dp, h)
        return y, tangent

    def _derivative(self, y: Array, p: Array) -> Array:
        """``dy/dt`` of ``y = (q, w_b)``."""
        q, w = y[:, 0:4], y[:, 4:7]
        qdot = 0.5 * (qx.right_theta_matrix(q) @ w[:, :, None])[:, :, 0]
        return namespace(y).concat((qdot, p * (w[:, _CYCLIC[0]] * w[:, _CYCLIC[1]])), axis=1)

    def _derivative_jacobian(self, y: Array, p: Array, dp: Array | None) -> Array:
        """``d(dy/dt)/d(y, k)`` ``(B, 7, 7 + r)`` (``r`` = 2 with estimated ratios, else 0)."""
        xp = namespace(y)
        batch = y.shape[0]
        q, w = y[:, 0:4], y[:, 4:7]
        rates = xp.reshape(w @ constant(y, "euler-rates", _rates_matrix), (batch, 3, 3))
        top = xp.concat((0.5 * qx.right_omega_matrix(w), 0.5 * qx.right_theta_matrix(q)), axis=2)
        bottom = [zeros(y, (batch, 3, 4)), p[:, :, None] * rates]
        if dp is not None:
            top = xp.concat((top, zeros(y, (batch, 4, 2))), axis=2)
            bottom.append((w[:, _CYCLIC[0]] * w[:, _CYCLIC[1]])[:, :, None] * dp)
        return xp.concat((top, xp.concat(bottom, axis=2)), axis=1)

    def _rk4_step(self, y: Array, tangent: Array | None, p: Array, dp: Array | None, h: float) -> tuple[Array, Array | None]:
        """One classical Runge-Kutta step of ``y`` and, when given, of its tangent
        ``d y / d(y0, k)`` (the stages' tangents through the dynamics' Jacobian)."""
        slopes, slope_tangents = [], []
        for weight in (0.0, 0.5, 0.5, 1.0):
            stage = y if weight == 0.0 else y + (weight * h) * slopes[-1]
            slopes.append(self._derivative(stage, p))
            if tangent is not None:
                stage_tangent = tangent if weight == 0.0 else tangent + (weight * h) * slope_tangents[-1]
                A = self._derivative_jacobian(stage, p, dp)
                slope_tangent = A[:, :, :7] @ stage_tangent
                if dp is not None:  # k enters through the stage state and, directly, through p(k)
                    slope_tangent = slope_tangent + _pad_left(A[:, :, 7:])
                slope_tangents.append(slope_tangent)
        k1, k2, k3, k4 = slopes
        y = y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        if tangent is not None:
            t1, t2, t3, t4 = slope_tangents
            tangent = tangent + (h / 6.0) * (t1 + 2.0 * t2 + 2.0 * t3 + t4)
        return y, tangent

    def _jacobian(self, x: Array, q1: Array, wb1: Array, tangent: Array, dt: float) -> Array:
        """``F (B, n, n)`` from the tangent ``d(q1, w_b1)/d(q0, w_b0, k)`` and the frame changes
        ``w_b0 = R(q0)^T w0`` and ``w1 = R(q1) w_b1``."""
        xp = namespace(x)
        batch, n = x.shape[0], self.state_dim
        q0, w0 = x[:, 0:4], x[:, 7:10]
        blank = lambda rows, cols: zeros(x, (batch, rows, cols))  # noqa: E731
        eye4 = xp.broadcast_to(constant(x, ("eye", 4), lambda: np.eye(4)), (batch, 4, 4))
        # into the body frame: d(q0, w_b0)/d(q0, w0); the rotations use the unit quaternion
        # u = q / |q|, so that the norm of q (which the additive filter lets drift between
        # updates, and removes from the covariance at each update) does not leak into the rate
        u0, u1 = _unit(q0), _unit(q1)
        into = xp.concat(
            (xp.concat((eye4, blank(4, 3)), axis=2),
             xp.concat((qx.rotation_jacobian(u0, w0, transpose=True) @ _unit_jacobian(q0), qx.rotation_matrix(u0).swapaxes(1, 2)), axis=2)),
            axis=1,
        )  # fmt: skip
        # back to the world frame: d(q1, w1)/d(q1, w_b1)
        out = xp.concat(
            (xp.concat((eye4, blank(4, 3)), axis=2),
             xp.concat((qx.rotation_jacobian(u1, wb1) @ _unit_jacobian(q1), qx.rotation_matrix(u1)), axis=2)),
            axis=1,
        )  # fmt: skip
        rotational = out @ (tangent[:, :, :7] @ into)  # d(q1, w1)/d(q0, w0)
        ratio = out @ tangent[:, :, 7:] if n == 15 else None  # d(q1, w1)/dk
        # the paper's layout: q 0:4, r 4:7, w 7:10, v 10:13 (, k 13:15)
        rows_q = [rotational[:, 0:4, 0:4], blank(4, 3), rotational[:, 0:4, 4:7], blank(4, 3)]
        rows_w = [rotational[:, 4:7, 0:4], blank(3, 3), rotational[:, 4:7, 4:7], blank(3, 3)]
        if ratio is not None:
            rows_q.append(ratio[:, 0:4])
            rows_w.append(ratio[:, 4:7])
        linear = constant(x, ("rigid-linear", n, dt), lambda: _linear_rows(n, dt), self._constants())
        return xp.concat(
            (xp.concat(rows_q, axis=2), xp.broadcast_to(linear[4:7], (batch, 3, n)),
             xp.concat(rows_w, axis=2), xp.broadcast_to(linear[10:], (batch, n - 10, n))),
            axis=1,
        )  # fmt: skip

    def initial_state(self, z: Array) -> Array:
        xp = namespace(z)
        x = xp.concat((z[:, :7], zeros(z, (z.shape[0], self.state_dim - 7))), axis=1)
        return x + self._ratio_offset(z) if self.estimate_ratios else x

    def prior_state(self, batch: int, dtype: Any) -> Array:
        x = prior_array(batch, self.state_dim, dtype, first=1.0)
        return x + self._ratio_offset(x) if self.estimate_ratios else x

    def _ratio_offset(self, like: Array) -> Array:
        """``(1, n)``: zeros but for the prior mean of the log ratios."""
        def make() -> np.ndarray:
            offset = np.zeros((1, self.state_dim))
            offset[0, 13:15] = self.ratio_prior
            return offset

        return constant(like, ("ratio-prior", self.ratio_prior), make, self._constants())


def _unit(q: Array) -> Array:
    """``q / |q|`` of ``(B, 4)`` quaternions."""
    return q / namespace(q).sqrt((q * q).sum(-1, keepdims=True))


def _unit_jacobian(q: Array) -> Array:
    """``d(q / |q|)/dq = (I - u u^T) / |q|`` ``(B, 4, 4)``."""
    norm = namespace(q).sqrt((q * q).sum(-1, keepdims=True))
    u = q / norm
    return (eye(q, 4) - u[:, :, None] * u[:, None, :]) / norm[:, :, None]


def _pad_left(direct: Array) -> Array:
    """``[0 | direct]`` ``(B, 7, 7 + r)``: the direct ratio terms of a stage's tangent."""
    xp = namespace(direct)
    return xp.concat((zeros(direct, (direct.shape[0], 7, 7)), direct), axis=2)


def _linear_rows(n: int, dt: float) -> np.ndarray:
    """``(n, n)``: the identity with ``r += dt v`` (the rows of ``r``, ``v`` and ``k``)."""
    A = np.eye(n)
    A[4:7, 10:13] = dt * np.eye(3)
    return A
