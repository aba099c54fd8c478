"""The rigid-body model's compiled kernels (numba): the propagation of single trajectories, which
the truth simulator runs (:class:`fkn_bench.envs.dynamics.FreeTumble`), and the model's transition
with its Jacobian on numpy input (:meth:`fkn_bench.models.rigid_body.RigidBodyModel.transition`).

The equations are :mod:`fkn_bench.models.rigid_body`'s: for ``y = [q (wxyz), w_b]`` (7,), the
attitude ``q`` rotating body to world and the body-frame rate ``w_b`` (rad/s),

    q' = 1/2 q (x) [0, w_b],    w_b' = p * (w_y w_z, w_z w_x, w_x w_y)    (Euler's equations)

with ``p = euler_coefficients(J)`` (:func:`fkn_bench.models.rigid_body.euler_coefficients`),
integrated by classical fourth-order Runge-Kutta steps (Landau & Lifshitz, Mechanics, sections
35-37; Markley & Crassidis, Fundamentals of Spacecraft Attitude Determination and Control, 2014,
ch. 3). Both kernels step with :func:`_derivative` (written once here):

* :func:`integrate_samples` integrates one trajectory at a time, with the quaternion renormalised
  at every sample (a simulator's convention; the model's transition does not renormalise);
* :func:`transition` is the model's numpy transition, row by row: the mean, and the Jacobian
  ``F = df/dx`` by the tangent of every Runge-Kutta stage (:func:`_derivative_jacobian`), the log
  inertia ratios' coefficients clipped to ``|p_i| <= 1`` and the step refined for fast rows, as
  the model's module docstring and ``RigidBodyModel._integrate`` state. The model's torch path
  (autograd) computes the same with batched operations; the two agree to rounding
  (``tests/models/test_rigid_body_kernels.py``).

Arithmetic: each result is a fixed sequence of IEEE operations (numba without ``fastmath``: no
fused multiply-adds, no reordering), so a row's results do not depend on the batch it is in, and
:func:`integrate_samples`'s samples are bit for bit those of the element-wise numpy formulas the
expressions are written as (``tests/envs/test_dynamics.py`` holds the kernel to such an
implementation).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from fkn_bench.types import ArrayF

__all__ = ["body_rates", "integrate_samples", "transition"]


@numba.njit(cache=True, inline="always")
def _rotate(w: float, x: float, y: float, z: float, vx: float, vy: float, vz: float) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """``R(q) v = q (x) [0, v] (x) q*`` for unit ``q = (w, x, y, z)``, expanded as
    ``v + w t + vec(q) x t`` with ``t = 2 vec(q) x v``."""
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return vx + w * tx + (y * tz - z * ty), vy + w * ty + (z * tx - x * tz), vz + w * tz + (x * ty - y * tx)


@numba.njit(cache=True)
def body_rates(q: ArrayF, omega_world: ArrayF) -> ArrayF:  # pragma: no cover - compiled
    """Body-frame rates ``R(q)^T w (B, 3)`` of world-frame rates ``omega_world (B, 3)`` (rad/s)
    for unit attitudes ``q (B, 4)``: the rotation by the conjugate ``(w, -x, -y, -z)``."""
    out = np.empty((q.shape[0], 3))
    for b in range(q.shape[0]):
        out[b, 0], out[b, 1], out[b, 2] = _rotate(q[b, 0], -q[b, 1], -q[b, 2], -q[b, 3],
                                                  omega_world[b, 0], omega_world[b, 1], omega_world[b, 2])
    return out


@numba.njit(cache=True)
def _derivative(y: ArrayF, p: ArrayF, out: ArrayF) -> None:  # pragma: no cover - compiled
    """``dy/dt`` of ``y = [q, w_b]`` (7,) into ``out``: ``q' = q (x) [0, w_b] / 2`` and Euler's
    equations ``w_x' = p_x w_y w_z`` (cyclic)."""
    w, x, yq, z = y[0], y[1], y[2], y[3]
    ox, oy, oz = y[4], y[5], y[6]
    out[0] = -0.5 * (x * ox + yq * oy + z * oz)
    out[1] = 0.5 * (w * ox + yq * oz - z * oy)
    out[2] = 0.5 * (w * oy + z * ox - x * oz)
    out[3] = 0.5 * (w * oz + x * oy - yq * ox)
    out[4] = p[0] * oy * oz
    out[5] = p[1] * oz * ox
    out[6] = p[2] * ox * oy


@numba.njit(cache=True)
def _rk4_step(state: ArrayF, p: ArrayF, h: float, k1: ArrayF, k2: ArrayF, k3: ArrayF, k4: ArrayF,
              trial: ArrayF) -> None:  # pragma: no cover - compiled
    """One classical Runge-Kutta step of ``h`` seconds of ``state`` (7,), in place (``k1 .. k4``
    and ``trial``: scratch of 7)."""
    _derivative(state, p, k1)
    for j in range(7):
        trial[j] = state[j] + (0.5 * h) * k1[j]
    _derivative(trial, p, k2)
    for j in range(7):
        trial[j] = state[j] + (0.5 * h) * k2[j]
    _derivative(trial, p, k3)
    for j in range(7):
        trial[j] = state[j] + h * k3[j]
    _derivative(trial, p, k4)
    for j in range(7):
        state[j] = state[j] + (h / 6.0) * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])


@numba.njit(cache=True)
def integrate_samples(y: ArrayF, p: ArrayF, h: float, substeps: int, started: bool,
                      q_out: ArrayF, w_out: ArrayF) -> None:  # pragma: no cover - compiled
    """Advance the states ``y = [q, w_b] (B, 7)`` (in place) by ``n = q_out.shape[0]`` samples and
    write each sample's attitude ``q_out (n, 4, B)`` and world-frame rate ``w_out (n, 3, B)``
    (rad/s); with Euler coefficients ``p (B, 3)`` (one row per trajectory). Between samples:
    ``substeps`` Runge-Kutta steps of ``h`` seconds, then ``q`` renormalised; the first sample is
    the current state when not ``started`` (a trajectory's first sample is its initial state)."""
    k1, k2, k3, k4, trial = np.empty(7), np.empty(7), np.empty(7), np.empty(7), np.empty(7)
    for b in range(y.shape[0]):
        state = y[b]
        for i in range(q_out.shape[0]):
            if started or i > 0:
                for _ in range(substeps):
                    _rk4_step(state, p[b], h, k1, k2, k3, k4, trial)
                norm = np.sqrt(state[0] * state[0] + state[1] * state[1] + state[2] * state[2] + state[3] * state[3])
                for j in range(4):
                    state[j] = state[j] / norm
            for j in range(4):
                q_out[i, j, b] = state[j]
            w_out[i, 0, b], w_out[i, 1, b], w_out[i, 2, b] = _rotate(state[0], state[1], state[2], state[3],
                                                                     state[4], state[5], state[6])


# ---------------------------------------------------------------------- the model's transition
@numba.njit(cache=True)
def _unit(q: ArrayF, u: ArrayF) -> float:  # pragma: no cover - compiled
    """``u = q / |q|`` (4,) in place of ``u``; returns ``|q|``."""
    norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    for i in range(4):
        u[i] = q[i] / norm
    return norm


@numba.njit(cache=True)
def _rotation_matrix(q: ArrayF, R: ArrayF) -> None:  # pragma: no cover - compiled
    """``R(q)`` (3, 3) into ``R``: the unit-quaternion formula of
    :func:`fkn_bench.geometry.quaternion.rotation_matrix` (``1 - 2 (y^2 + z^2)``, ...)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    R[0, 0], R[0, 1], R[0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    R[1, 0], R[1, 1], R[1, 2] = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    R[2, 0], R[2, 1], R[2, 2] = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)


@numba.njit(cache=True)
def _rotation_jacobian(q: ArrayF, v: ArrayF, transpose: bool, J: ArrayF) -> None:  # pragma: no cover - compiled
    """``d(R(q) v)/dq`` (3, 4) into ``J`` (with ``transpose``: of ``R(q)^T v``), the exact
    derivative of :func:`_rotation_matrix`'s formula (quadratic in ``q``), as
    :func:`fkn_bench.geometry.quaternion.rotation_jacobian`. ``R(q)^T`` is the formula at the
    conjugate ``(w, -x, -y, -z)``, so its derivative is the one there with columns 1-3 negated."""
    s = -1.0 if transpose else 1.0
    w, x, y, z = q[0], s * q[1], s * q[2], s * q[3]
    v0, v1, v2 = v[0], v[1], v[2]
    J[0, 0], J[0, 1] = -2 * z * v1 + 2 * y * v2, 2 * y * v1 + 2 * z * v2
    J[0, 2], J[0, 3] = -4 * y * v0 + 2 * x * v1 + 2 * w * v2, -4 * z * v0 - 2 * w * v1 + 2 * x * v2
    J[1, 0], J[1, 1] = 2 * z * v0 - 2 * x * v2, 2 * y * v0 - 4 * x * v1 - 2 * w * v2
    J[1, 2], J[1, 3] = 2 * x * v0 + 2 * z * v2, 2 * w * v0 - 4 * z * v1 + 2 * y * v2
    J[2, 0], J[2, 1] = -2 * y * v0 + 2 * x * v1, 2 * z * v0 + 2 * w * v1 - 4 * x * v2
    J[2, 2], J[2, 3] = -2 * w * v0 + 2 * z * v1 - 4 * y * v2, 2 * x * v0 + 2 * y * v1
    for i in range(3):
        for j in range(1, 4):
            J[i, j] = s * J[i, j]


@numba.njit(cache=True)
def _ratio_coefficients(k1: float, k2: float, p: ArrayF, dp: ArrayF) -> None:  # pragma: no cover - compiled
    """Euler coefficients ``p`` (3,) and ``dp/dk`` (3, 2) of the log inertia ratios
    ``k = (k1, k2)``: ``p_x = e^-k1 - e^-(k1+k2)``, ``p_y = e^-k2 - e^k1``,
    ``p_z = e^(k1+k2) - e^k2``; a ``p_i`` outside the physical ``[-1, 1]`` (or NaN) is clipped, with
    zero derivative (``fkn_bench.models.rigid_body._coefficients_and_derivative``, which the
    torch path uses)."""
    a, b, ab = math.exp(k1), math.exp(k2), math.exp(k1 + k2)
    ia, ib, iab = 1.0 / a, 1.0 / b, 1.0 / ab
    p[0], p[1], p[2] = ia - iab, ib - a, ab - b
    dp[0, 0], dp[0, 1], dp[1, 0], dp[1, 1], dp[2, 0], dp[2, 1] = iab - ia, iab, -a, -ib, ab, ab - b
    for i in range(3):
        if not abs(p[i]) <= 1.0:
            if p[i] > 1.0:
                p[i] = 1.0
            elif p[i] < -1.0:
                p[i] = -1.0
            dp[i, 0], dp[i, 1] = 0.0, 0.0


@numba.njit(cache=True)
def _derivative_jacobian(y: ArrayF, p: ArrayF, dp: ArrayF, A: ArrayF) -> None:  # pragma: no cover - compiled
    """``d(dy/dt)/d(y, k)`` (7, 7 + r) of :func:`_derivative` into ``A``, with ``dp = dp/dk``
    (3, r) (``r = 0`` for a known inertia): ``0.5 Omega_R(w_b)`` and ``0.5 Theta_R(q)`` in the
    quaternion rows, Euler's equations bilinear in ``p`` and ``w_b`` below."""
    w, x, yq, z = y[0], y[1], y[2], y[3]
    ox, oy, oz = y[4], y[5], y[6]
    A[:, :] = 0.0
    A[0, 1], A[0, 2], A[0, 3] = -0.5 * ox, -0.5 * oy, -0.5 * oz
    A[1, 0], A[1, 2], A[1, 3] = 0.5 * ox, 0.5 * oz, -0.5 * oy
    A[2, 0], A[2, 1], A[2, 3] = 0.5 * oy, -0.5 * oz, 0.5 * ox
    A[3, 0], A[3, 1], A[3, 2] = 0.5 * oz, 0.5 * oy, -0.5 * ox
    A[0, 4], A[0, 5], A[0, 6] = -0.5 * x, -0.5 * yq, -0.5 * z
    A[1, 4], A[1, 5], A[1, 6] = 0.5 * w, -0.5 * z, 0.5 * yq
    A[2, 4], A[2, 5], A[2, 6] = 0.5 * z, 0.5 * w, -0.5 * x
    A[3, 4], A[3, 5], A[3, 6] = -0.5 * yq, 0.5 * x, 0.5 * w
    A[4, 5], A[4, 6] = p[0] * oz, p[0] * oy
    A[5, 4], A[5, 6] = p[1] * oz, p[1] * ox
    A[6, 4], A[6, 5] = p[2] * oy, p[2] * ox
    for j in range(dp.shape[1]):
        A[4, 7 + j], A[5, 7 + j], A[6, 7 + j] = oy * oz * dp[0, j], oz * ox * dp[1, j], ox * oy * dp[2, j]


@numba.njit(cache=True)
def _rk4_tangent_step(state: ArrayF, T: ArrayF, p: ArrayF, dp: ArrayF, h: float, k: ArrayF, Tk: ArrayF,
                      trial: ArrayF, Tt: ArrayF, A: ArrayF) -> None:  # pragma: no cover - compiled
    """:func:`_rk4_step` (the same operations on ``state``) with the tangent ``T = dy/d(y0, k)``
    (7, 7 + r), in place: each stage's tangent is ``A T_stage + [0 | A_k]``, ``A`` the
    :func:`_derivative_jacobian` at the stage (``k`` (4, 7), ``Tk`` (4, 7, 7 + r), ``trial``,
    ``Tt`` and ``A``: scratch)."""
    m = T.shape[1]
    for s in range(4):
        c = 0.0 if s == 0 else (h if s == 3 else 0.5 * h)
        for i in range(7):
            trial[i] = state[i] if s == 0 else state[i] + c * k[s - 1, i]
            for j in range(m):
                Tt[i, j] = T[i, j] if s == 0 else T[i, j] + c * Tk[s - 1, i, j]
        _derivative(trial, p, k[s])
        _derivative_jacobian(trial, p, dp, A)
        for i in range(7):
            for j in range(m):
                acc = A[i, j] if j >= 7 else 0.0  # k enters directly, through p(k)
                for l in range(7):
                    acc += A[i, l] * Tt[l, j]
                Tk[s, i, j] = acc
    for i in range(7):
        state[i] = state[i] + (h / 6.0) * (k[0, i] + 2.0 * k[1, i] + 2.0 * k[2, i] + k[3, i])
        for j in range(m):
            T[i, j] = T[i, j] + (h / 6.0) * (Tk[0, i, j] + 2.0 * Tk[1, i, j] + 2.0 * Tk[2, i, j] + Tk[3, i, j])


@numba.njit(cache=True)
def _matmul(A: ArrayF, B: ArrayF, C: ArrayF) -> None:  # pragma: no cover - compiled
    """``C = A B`` of small matrices."""
    for i in range(A.shape[0]):
        for j in range(B.shape[1]):
            acc = 0.0
            for l in range(A.shape[1]):
                acc += A[i, l] * B[l, j]
            C[i, j] = acc


@numba.njit(cache=True)
def _frame_jacobian(q: ArrayF, v: ArrayF, transpose: bool, out: ArrayF, R: ArrayF, J: ArrayF, N: ArrayF,
                    u: ArrayF) -> None:  # pragma: no cover - compiled
    """``d(q, R(u) v)/d(q, v)`` (7, 7) into ``out`` for ``u = q / |q|`` (with ``transpose``:
    ``R(u)^T v``): the identity on ``q``, ``d(R(u) v)/du (I - u u^T) / |q|`` and ``R(u)`` (or its
    transpose) below (``R`` (3, 3), ``J`` (3, 4), ``N`` (4, 4), ``u`` (4,): scratch)."""
    norm = _unit(q, u)
    _rotation_matrix(u, R)
    _rotation_jacobian(u, v, transpose, J)
    for i in range(4):
        for j in range(4):
            N[i, j] = ((1.0 if i == j else 0.0) - u[i] * u[j]) / norm
    out[:, :] = 0.0
    for i in range(4):
        out[i, i] = 1.0
    _matmul(J, N, out[4:7, 0:4])
    for i in range(3):
        for j in range(3):
            out[4 + i, 4 + j] = R[j, i] if transpose else R[i, j]


@numba.njit(cache=True)
def transition(x: ArrayF, p_known: ArrayF, dt: float, substeps: int, max_substeps: int, jacobian: bool,
               mean: ArrayF, F: ArrayF) -> None:  # pragma: no cover - compiled
    """:meth:`fkn_bench.models.rigid_body.RigidBodyModel.transition` of states ``x (B, n)``
    (``[q, r, w, v]``, ``n = 13``, with Euler coefficients ``p_known (3,)``; or followed by the
    log ratios ``k``, ``n = 15``, ``p_known`` unused) over ``dt`` seconds: the next states into
    ``mean (B, n)`` and, with ``jacobian``, ``F = df/dx`` into ``F (B, n, n)`` (else unused).

    A row whose step needs ``(4 dt) |w_b| (1/2 + max|p|)`` Runge-Kutta steps with more than
    ``substeps`` of them is integrated in ``ceil(min(needed, max_substeps))`` steps, the most
    any such row of the batch needs; the others in ``substeps`` (``RigidBodyModel._integrate``).
    The Jacobian is ``out T into`` (``into = d(q0, w_b0)/d(q0, w0)``, ``T`` the Runge-Kutta
    tangent, ``out = d(q1, w1)/d(q1, w_b1)``), the rotations by the unit quaternions, with
    ``r' = r + dt v`` and the identity on ``v`` and ``k``."""
    batch, n = x.shape
    r = n - 13
    m = 7 + r
    p, dp, y0 = np.empty((batch, 3)), np.zeros((batch, 3, r)), np.empty((batch, 7))
    needed, steps = np.empty(batch), np.empty(batch, np.int64)
    u, R, J, N = np.empty(4), np.empty((3, 3)), np.empty((3, 4)), np.empty((4, 4))
    top = 0.0
    for b in range(batch):  # coefficients, body rates and the steps each row needs
        if r:
            _ratio_coefficients(x[b, 13], x[b, 14], p[b], dp[b])
        else:
            p[b, 0], p[b, 1], p[b, 2] = p_known[0], p_known[1], p_known[2]
        _unit(x[b, 0:4], u)
        _rotation_matrix(u, R)
        for i in range(4):
            y0[b, i] = x[b, i]
        for i in range(3):
            y0[b, 4 + i] = R[0, i] * x[b, 7] + R[1, i] * x[b, 8] + R[2, i] * x[b, 9]
        rate = math.sqrt(y0[b, 4] * y0[b, 4] + y0[b, 5] * y0[b, 5] + y0[b, 6] * y0[b, 6])
        needed[b] = (4.0 * dt) * (rate * (0.5 + max(abs(p[b, 0]), abs(p[b, 1]), abs(p[b, 2]))))
        if needed[b] > substeps and needed[b] > top:  # (NaN compares False: nothing to refine)
            top = needed[b]
    wild_steps = int(math.ceil(min(top, float(max_substeps))))
    for b in range(batch):
        steps[b] = wild_steps if needed[b] > substeps else substeps
    state, trial = np.empty(7), np.empty(7)
    k, Tk = np.empty((4, 7)), np.empty((4, 7, m))
    T, Tt, A = np.empty((7, m)), np.empty((7, m)), np.empty((7, m))
    into, out, G, rotational = np.empty((7, 7)), np.empty((7, 7)), np.empty((7, 7)), np.empty((7, 7))
    ratio = np.empty((7, r))
    rows = (0, 1, 2, 3, 7, 8, 9)  # (q, w) in the state of y = (q, w_b)
    for b in range(batch):
        state[:] = y0[b]
        if jacobian:
            T[:, :] = 0.0
            for i in range(7):
                T[i, i] = 1.0
        h = dt / steps[b]
        for _ in range(steps[b]):
            if jacobian:
                _rk4_tangent_step(state, T, p[b], dp[b], h, k, Tk, trial, Tt, A)
            else:
                _rk4_step(state, p[b], h, k[0], k[1], k[2], k[3], trial)
        _unit(state[0:4], u)
        _rotation_matrix(u, R)
        for i in range(4):
            mean[b, i] = state[i]
        for i in range(3):
            mean[b, 4 + i] = x[b, 4 + i] + dt * x[b, 10 + i]
            mean[b, 7 + i] = R[i, 0] * state[4] + R[i, 1] * state[5] + R[i, 2] * state[6]
        for i in range(10, n):
            mean[b, i] = x[b, i]
        if not jacobian:
            continue
        _frame_jacobian(x[b, 0:4], x[b, 7:10], True, into, R, J, N, u)
        _frame_jacobian(state[0:4], state[4:7], False, out, R, J, N, u)
        _matmul(T[:, 0:7], into, G)
        _matmul(out, G, rotational)  # d(q1, w1)/d(q0, w0)
        _matmul(out, T[:, 7:], ratio)  # d(q1, w1)/dk
        F[b, :, :] = 0.0
        for i in range(7):
            for j in range(7):
                F[b, rows[i], rows[j]] = rotational[i, j]
            for j in range(r):
                F[b, rows[i], 13 + j] = ratio[i, j]
        for i in range(3):
            F[b, 4 + i, 4 + i] = 1.0
            F[b, 4 + i, 10 + i] = dt
        for i in range(10, n):
            F[b, i, i] = 1.0
