"""Ground-truth rigid-body motion of the target: forced rotation and torque-free tumbling.

Both propagators are *chunked*: :meth:`advance` returns the next ``n`` samples and keeps the state,
so an episode can be generated all at once or piece by piece with identical results (the
single and the vector environment rely on this). Only element-wise arithmetic is used along the
batch axis, so a batch of episodes gives bit-identical samples to the same episodes one by one.

Frames: ``q`` rotates body to world (Hamilton, wxyz); ``omega`` in the output is the world-frame
angular velocity (rad/s), as in the paper's state vector. Outputs are *component-major*:
``(B, 4, n)`` attitudes and ``(B, 3, n)`` rates, which keeps numpy's inner loops long.

References
    * Forced rotation at constant world-frame rate: ``q(t) = exp(omega t / 2) (x) q0``, the exact
      solution of ``q' = 1/2 [0, omega] (x) q`` (FlexKalmanNet eqs. 9 and 11; Sola 2017, eq. 214).
    * Torque-free motion: Euler's equations ``J dw/dt = -w x (J w)`` for the body rate ``w`` and
      ``q' = 1/2 q (x) [0, w]`` (Landau & Lifshitz, Mechanics, sections 35-37; Markley &
      Crassidis, Fundamentals of Spacecraft Attitude Determination and Control, 2014, ch. 3),
      integrated with the classical fourth-order Runge-Kutta method: the rigid-body model's
      propagation (:mod:`fkn_bench.models.rigid_body`), which the simulator calls
      (:mod:`fkn_bench.models.rigid_body_kernels`) instead of writing the physics again.
"""

from __future__ import annotations

import numpy as np

from fkn_bench.geometry import quaternion as quat
from fkn_bench.models.rigid_body import euler_coefficients
from fkn_bench.types import ArrayF

__all__ = ["ForcedRotation", "FreeTumble", "PerturbedRotation"]


class _RandomAccess:
    """A propagator with random access (:meth:`sample` any step range), walked by
    :meth:`advance` from the step :meth:`seek` sets."""

    _index: int

    def sample(self, start: int, n: int, *, step_major: bool = False) -> tuple[ArrayF, ArrayF]:
        raise NotImplementedError

    def advance(self, n: int, *, step_major: bool = False) -> tuple[ArrayF, ArrayF]:
        """Next ``n`` samples (see :meth:`sample`)."""
        out = self.sample(self._index, n, step_major=step_major)
        self._index += n
        return out

    def seek(self, index: int) -> None:
        """Continue from sample ``index``."""
        self._index = int(index)


class ForcedRotation(_RandomAccess):
    """Constant world-frame angular velocity; attitude from the exact quaternion exponential.

    Random access: :meth:`sample` evaluates any step range in closed form.

    Args:
        attitude0: initial attitudes ``(B, 4)`` (unit, wxyz).
        omega_world: world-frame angular velocities ``(B, 3)``, rad/s.
        dt: sample interval, s.
    """

    def __init__(self, attitude0: ArrayF, omega_world: ArrayF, dt: float) -> None:
        self._q0 = np.array(attitude0, dtype=float)
        self._omega = np.array(omega_world, dtype=float)
        self._dt = float(dt)
        rate = np.sqrt(np.sum(self._omega**2, axis=1))
        self._rate = rate  # rad/s
        axis = self._omega / np.where(rate > 0, rate, 1.0)[:, None]
        self._axis_q0 = quat.multiply(np.concatenate([np.zeros((len(rate), 1)), axis], axis=1), self._q0)
        # component-major copies for the step-major layout (broadcasting over a strided inner
        # axis is 4x slower)
        self._q0_t, self._axis_q0_t = np.ascontiguousarray(self._q0.T), np.ascontiguousarray(self._axis_q0.T)
        self._omega_t = np.ascontiguousarray(self._omega.T)
        self._index = 0

    def sample(self, start: int, n: int, *, step_major: bool = False) -> tuple[ArrayF, ArrayF]:
        """Samples ``start .. start+n-1``: attitudes ``(B, 4, n)`` and rates ``(B, 3, n)``
        (``step_major``: ``(n, 4, B)`` and ``(n, 3, B)``, the same values).

        With ``h = |omega| t / 2`` and axis ``u``: ``exp(omega t / 2) (x) q0 =
        cos(h) q0 + sin(h) ([0, u] (x) q0)``, two precomputed quaternions per episode.
        """
        times = np.arange(start, start + n) * self._dt
        if step_major:
            half_angle = 0.5 * self._rate[None, :] * times[:, None]
            q = np.multiply(np.cos(half_angle)[:, None, :], self._q0_t[None])
            q += np.sin(half_angle)[:, None, :] * self._axis_q0_t[None]
            return q, np.broadcast_to(self._omega_t[None], (n, 3, len(self._rate)))
        half_angle = 0.5 * self._rate[:, None] * times[None, :]
        q = np.multiply(np.cos(half_angle)[:, None, :], self._q0[:, :, None])
        q += np.sin(half_angle)[:, None, :] * self._axis_q0[:, :, None]
        return q, np.broadcast_to(self._omega[:, :, None], (len(self._rate), 3, n))


class PerturbedRotation(_RandomAccess):
    """Forced rotation whose world-frame rate is ``omega_world + offsets[k]`` over step ``k``
    (unmodelled torque bursts, :func:`fkn_bench.envs.episodes.rate_offsets`): ``q_{k+1} =
    exp((omega + d_k) dt / 2) (x) q_k``, each factor exact for a rate constant over the step.

    The whole episode is evaluated at construction (its ``N`` increments by one vectorised
    quaternion exponential, their product by a prefix scan of ``log2 N`` vectorised products,
    renormalised), so that :meth:`sample` is random access like :class:`ForcedRotation`'s.

    Args:
        attitude0: initial attitudes ``(B, 4)``.
        omega_world: nominal world-frame angular velocities ``(B, 3)``, rad/s.
        offsets: rate offsets ``(B, N, 3)`` of the episode's ``N`` steps, rad/s.
        dt: sample interval, s.
    """

    def __init__(self, attitude0: ArrayF, omega_world: ArrayF, offsets: ArrayF, dt: float) -> None:
        omega = np.asarray(omega_world, dtype=float)[:, None, :] + np.asarray(offsets, dtype=float)
        batch, steps, _ = omega.shape
        # increments e_k = exp(omega_k dt / 2) (step k -> k + 1); the prefix products
        # P_k = e_{k-1} (x) ... (x) e_0 by a Hillis-Steele scan (later factors on the left)
        product = np.empty((batch, steps, 4))
        product[:, 0] = (1.0, 0.0, 0.0, 0.0)
        product[:, 1:] = quat.from_rotation_vector(omega[:, :-1] * float(dt))
        shift = 1
        while shift < steps:
            product[:, shift:] = quat.multiply(product[:, shift:], product[:, :-shift])
            shift *= 2
        q = quat.multiply(product, np.broadcast_to(np.asarray(attitude0, dtype=float)[:, None, :], product.shape))
        self._q = quat.normalize(q).transpose(0, 2, 1)  # (B, 4, N)
        self._omega = omega.transpose(0, 2, 1)  # (B, 3, N)
        self._index = 0

    def sample(self, start: int, n: int, *, step_major: bool = False) -> tuple[ArrayF, ArrayF]:
        """Samples ``start .. start+n-1``: attitudes ``(B, 4, n)`` and rates ``(B, 3, n)``
        (``step_major``: ``(n, 4, B)`` and ``(n, 3, B)``, the same values)."""
        q, omega = self._q[:, :, start : start + n], self._omega[:, :, start : start + n]
        if step_major:
            return np.ascontiguousarray(q.transpose(2, 1, 0)), np.ascontiguousarray(omega.transpose(2, 1, 0))
        return q.copy(), omega.copy()


class FreeTumble:
    """Torque-free rigid body with principal moments ``inertia``, integrated with RK4.

    The propagation is the rigid-body model's (:mod:`fkn_bench.models.rigid_body`: Euler's
    equations with :func:`~fkn_bench.models.rigid_body.euler_coefficients` and the quaternion
    kinematics), run compiled one trajectory at a time
    (:func:`fkn_bench.models.rigid_body_kernels.integrate_samples`). Each sample interval ``dt``
    is split into ``substeps`` RK4 steps; the quaternion is renormalised at every sample (the
    integrator itself does not). With Astrobee's inertia and ``dt = 0.1`` s, one sub-step
    conserves kinetic energy and world-frame angular momentum to about 1e-13 (ds1 rates) and
    4e-10 (ds2 rates) relative over 16000 samples.

    Args:
        attitude0: initial attitudes ``(B, 4)``.
        omega_world0: initial world-frame angular velocities ``(B, 3)``, rad/s.
        inertia: principal moments ``(Jx, Jy, Jz)`` of the body axes, kg m^2: one triple for the
            batch, or ``(B, 3)`` (one per episode).
        dt: sample interval, s.
        substeps: RK4 steps per sample interval.
    """

    def __init__(
        self,
        attitude0: ArrayF,
        omega_world0: ArrayF,
        inertia: tuple[float, float, float] | ArrayF,
        dt: float,
        substeps: int = 1,
    ) -> None:
        q0 = np.array(attitude0, dtype=float)
        J = np.broadcast_to(np.array(inertia, dtype=float), (q0.shape[0], 3))
        self._coeff = np.array([euler_coefficients(row) for row in J]).reshape(-1, 3)  # (B, 3)
        from fkn_bench.models.rigid_body_kernels import body_rates  # numba: imported where a tumble is simulated

        omega_body = body_rates(q0, np.ascontiguousarray(omega_world0, dtype=float))
        self._y = np.concatenate([q0, omega_body], axis=1)
        self._h = float(dt) / int(substeps)
        self._substeps = int(substeps)
        self._started = False

    def advance(self, n: int, *, step_major: bool = False) -> tuple[ArrayF, ArrayF]:
        """Next ``n`` samples: attitudes ``(B, 4, n)`` and world-frame rates ``(B, 3, n)``
        (``step_major``: ``(n, 4, B)`` and ``(n, 3, B)``, the same values)."""
        batch = self._y.shape[0]
        q_out = np.empty((n, 4, batch))
        w_out = np.empty((n, 3, batch))
        y = np.ascontiguousarray(self._y)
        from fkn_bench.models.rigid_body_kernels import integrate_samples

        integrate_samples(y, self._coeff, self._h, self._substeps, self._started, q_out, w_out)
        self._started = self._started or n > 0
        self._y = y
        if step_major:
            return q_out, w_out
        return q_out.transpose(2, 1, 0), w_out.transpose(2, 1, 0)

