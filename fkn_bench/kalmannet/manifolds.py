"""Where KalmanNet's differences and corrections live: plain vectors, or the pose's tangent space.

KalmanNet (Revach et al. 2022, section "KalmanNet": its input features and update) forms four differences of measurements
and states and applies its learned gain to the innovation additively,
``x_t|t = x_t|t-1 + K_t dy_t``. For a state with a unit quaternion an additive difference is not
sign-safe (``q`` and ``-q`` are one attitude) and an additive correction leaves the unit sphere.
A :class:`Manifold` says how to take differences (``boxminus``) and how to apply a correction
(``boxplus``), in the measurement space and in the state space:

* :class:`Euclidean`: ``a - b`` and ``x + d`` (the paper's own, for a linear model).
* :class:`PoseTangent`: the project's pose state ``[q(4), r(3), w(3), v(3)]`` (Hamilton,
  scalar-first ``wxyz``, body to world; :mod:`fkn_bench.types`) with measurement ``[q, r]``. The
  attitude part of a difference is the world-frame rotation vector (rad) of the shortest rotation
  from ``b`` to ``a``, ``dtheta = Log(q_a (x) q_b*)``, taken after aligning signs (so it does not
  change when either quaternion is negated); the rest is subtracted. Differences are therefore
  ``(6,)`` for measurements ``[dtheta, dr]`` and ``(12,)`` for states ``[dtheta, dr, dw, dv]``
  (the project's error-state order, :data:`fkn_bench.types.ERROR_NAMES`). A correction rotates
  the attitude, ``q+ = Exp(dtheta) (x) q-``, and adds the rest. The gain is then ``(12, 6)``.

Both work on numpy arrays and torch tensors with a leading batch axis (``(B, k)``), so the
batched (training) and the online path share them. Every map is finite for any finite input,
including the all-zero placeholder of a missing measurement (no NaN can reach a gradient through
a ``where``).
"""

from __future__ import annotations


import numpy as np

from fkn_bench.models.base import StateSpaceModel
from fkn_bench.geometry import quaternion as qx
from fkn_bench.linalg import namespace
from fkn_bench.types import Array

__all__ = ["Manifold", "Euclidean", "PoseTangent", "manifold_for"]



class Manifold:
    """How differences and corrections are formed (see module docstring).

    Attributes:
        state_dim, measurement_dim: sizes of the model's state and measurement vectors.
        state_tangent_dim, measurement_tangent_dim: sizes of their differences (the gain is
            ``(state_tangent_dim, measurement_tangent_dim)``).
    """

    name: str
    state_dim: int
    measurement_dim: int
    state_tangent_dim: int
    measurement_tangent_dim: int

    def measurement_difference(self, a: Array, b: Array) -> Array:
        """``a [-] b`` of measurements ``(B, m)`` -> ``(B, m')``."""
        raise NotImplementedError

    def state_difference(self, a: Array, b: Array) -> Array:
        """``a [-] b`` of states ``(B, n)`` -> ``(B, n')``."""
        raise NotImplementedError

    def correct(self, x: Array, delta: Array) -> Array:
        """``x [+] delta`` of states ``(B, n)`` and corrections ``(B, n')``."""
        raise NotImplementedError

    def state_error(self, estimate: Array, truth: Array) -> Array:
        """Component-wise error ``(..., n)`` used by the training loss (sign-safe for a quaternion)."""
        return estimate - truth

    def observed_gain(self) -> np.ndarray:
        """``G (n', m')``: the gain that moves the observed part of the state onto the
        measurement and leaves the rest (``H G = I`` in tangent coordinates); a starting point
        for the learned gain (``initial_gain * G``)."""
        raise NotImplementedError

    def measurement_matrix(self) -> np.ndarray:
        """``H (m', n')``: the measurement's tangent as a linear map of the state's (what a
        covariance in tangent coordinates is observed through)."""
        raise NotImplementedError


class Euclidean(Manifold):
    """Plain vector differences and additive corrections (KalmanNet's own update)."""

    name = "euclidean"

    def __init__(self, H: np.ndarray) -> None:
        self.H = np.asarray(H, dtype=np.float64)
        self.measurement_dim, self.state_dim = self.H.shape
        self.state_tangent_dim, self.measurement_tangent_dim = self.state_dim, self.measurement_dim

    def observed_gain(self) -> np.ndarray:
        return np.linalg.pinv(self.H)  # H G = I for a full-row-rank H

    def measurement_matrix(self) -> np.ndarray:
        return self.H

    def measurement_difference(self, a: Array, b: Array) -> Array:
        return a - b

    def state_difference(self, a: Array, b: Array) -> Array:
        return a - b

    def correct(self, x: Array, delta: Array) -> Array:
        return x + delta


def _attitude_difference(qa: Array, qb: Array) -> Array:
    """World-frame rotation vector (rad) of the shortest rotation taking ``qb`` to ``qa``:
    ``Log(qa (x) qb*)``; the same for ``+-qa`` and ``+-qb`` (``to_rotation_vector`` picks the
    sign with a non-negative scalar part)."""
    return qx.to_rotation_vector(qx.multiply(qa, qx.conjugate(qb)))


class PoseTangent(Manifold):
    """The pose state's tangent space (see module docstring): 13 -> 12 and 7 -> 6."""

    name = "pose-tangent"
    state_dim, measurement_dim = 13, 7
    state_tangent_dim, measurement_tangent_dim = 12, 6

    def measurement_difference(self, a: Array, b: Array) -> Array:
        xp = namespace(a)
        return xp.concat((_attitude_difference(a[:, 0:4], b[:, 0:4]), a[:, 4:7] - b[:, 4:7]), axis=1)

    def state_difference(self, a: Array, b: Array) -> Array:
        xp = namespace(a)
        return xp.concat((_attitude_difference(a[:, 0:4], b[:, 0:4]), a[:, 4:] - b[:, 4:]), axis=1)

    def correct(self, x: Array, delta: Array) -> Array:
        xp = namespace(x)
        q = qx.multiply(qx.from_rotation_vector(delta[:, 0:3]), x[:, 0:4])  # Exp(dtheta) (x) q-, world frame
        return xp.concat((q, x[:, 4:] + delta[:, 3:]), axis=1)

    def observed_gain(self) -> np.ndarray:
        return np.eye(12, 6)  # [I6; 0]: attitude and position observed, rates not

    def measurement_matrix(self) -> np.ndarray:
        return np.eye(6, 12)  # [I6 0]: the pose error [dtheta, dr] of the state error

    def state_error(self, estimate: Array, truth: Array) -> Array:
        """``estimate - truth`` with the true quaternion's sign matched to the estimate (the
        project's 13-state error, :func:`fkn_bench.training.objectives.aligned_state_error`)."""
        from fkn_bench.training.objectives import aligned_state_error

        return aligned_state_error(estimate, truth)


def manifold_for(model: StateSpaceModel, kind: str = "auto") -> Manifold:
    """The manifold of ``model``: ``"pose-tangent"`` for the project's pose state (13 states with
    the quaternion first, 7 measurements ``[q, r]``), ``"euclidean"`` otherwise; ``kind`` forces one
    (``"auto"``: by the model's dimensions, so that any process model of the pose state, e.g. a
    rigid-body model with the same interface, gets the tangent space unchanged)."""
    n, m = int(model.state_dim), int(model.measurement_dim)
    if kind == "auto":
        kind = "pose-tangent" if (n, m) == (13, 7) else "euclidean"
    if kind == "pose-tangent":
        if (n, m) != (13, 7):
            raise ValueError(f"the pose tangent space needs 13 states and 7 measurements (model has {n} and {m})")
        return PoseTangent()
    if kind == "euclidean":
        return Euclidean(model.H)
    raise ValueError(f"manifold must be 'auto', 'pose-tangent' or 'euclidean' (got {kind!r})")
