"""The rigid-body model's compiled propagation of single trajectories (numba), which the truth
simulator runs (:class:`fkn_bench.envs.dynamics.FreeTumble`).

The equations are :mod:`fkn_bench.models.rigid_body`'s: for ``y = [q (wxyz), w_b]`` (7,), the
attitude ``q`` rotating body to world and the body-frame rate ``w_b`` (rad/s),

    q' = 1/2 q (x) [0, w_b],    w_b' = p * (w_y w_z, w_z w_x, w_x w_y)    (Euler's equations)

with ``p = euler_coefficients(J)`` (:func:`fkn_bench.models.rigid_body.euler_coefficients`),
integrated by classical fourth-order Runge-Kutta steps (Landau & Lifshitz, Mechanics, sections
35-37; Markley & Crassidis, Fundamentals of Spacecraft Attitude Determination and Control, 2014,
ch. 3). The model's batched numpy/torch transition (:class:`~fkn_bench.models.rigid_body.RigidBodyModel`)
integrates the same equations with their tangent for the filters; here one row is integrated at
a time in scalar float64 arithmetic, with the quaternion renormalised at every sample (a
simulator's convention; the model's transition does not renormalise).

Arithmetic: each result is a fixed sequence of IEEE operations (numba without ``fastmath``: no
fused multiply-adds, no reordering), so a row's samples do not depend on the batch it is in, and
they are bit for bit those of the element-wise numpy formulas the expressions are written as
(``tests/envs/test_dynamics.py`` holds the kernel to such an implementation).
"""

from __future__ import annotations

import numba
import numpy as np

from fkn_bench.types import ArrayF

__all__ = ["body_rates", "integrate_samples"]


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
