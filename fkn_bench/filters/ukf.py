"""Unscented Kalman filter, batched and differentiable, on the same models and noise layout.

Prediction by the unscented transform with the scaled sigma points of van der Merwe (2004,
"Sigma-point Kalman filters for probabilistic inference in dynamic state-space models", PhD
thesis, ch. 3): ``2n + 1`` points ``x``, ``x +- sqrt(n + lambda) L_i`` with ``L L^T = P`` and
``lambda = alpha^2 (n + kappa) - n``; weights ``Wm0 = lambda / (n + lambda)``,
``Wc0 = Wm0 + 1 - alpha^2 + beta``, ``Wi = 1 / (2 (n + lambda))``. Defaults ``alpha = 1``,
``beta = 2``, ``kappa = 0`` keep every mean weight non-negative.

Both models here measure linearly (``y = H x``); for a linear measurement the unscented
measurement update equals the Kalman update exactly, so the update reuses the EKF's Joseph form
(with the quaternion renormalisation and projection of the model).

The posterior covariance of the pose model is singular along the quaternion (the projection
removes that direction, which the model names through ``null_direction``). The sigma points are
then drawn from ``P + eps_n e e^T`` with ``e`` that unit direction and
``eps_n = max(1e-10, 100 eps_machine) max diag(P)`` (1e-10 in float64; in float32 1e-10 is below
the rounding of a 13x13 Cholesky factorisation, which then failed at about one step in ten):
full rank for the Cholesky factor, and the tangent-space spread unchanged. A Cholesky failure
that remains (it should not) falls back to ``P + sqrt(eps) mean(diag(P)) I`` for that row.
"""

from __future__ import annotations


import numpy as np

from fkn_bench.filters.base import FilterState, KalmanFilter
from fkn_bench.filters.ekf import linear_measurement_update
from fkn_bench.models.base import StateSpaceModel
from fkn_bench.models.pose_twist import PoseTwistModel
from fkn_bench.linalg import cholesky, constant, eye, namespace, symmetrize
from fkn_bench.types import Array

__all__ = ["UnscentedKalmanFilter", "sigma_point_weights"]



def _diagonal(P: Array) -> Array:
    """``(B, k)`` diagonals of ``(B, k, k)`` matrices."""
    return namespace(P).diagonal(P, axis1=1, axis2=2) if isinstance(P, np.ndarray) else P.diagonal(dim1=1, dim2=2)


_EPS: dict = {}


def _eps(P: Array) -> float:
    """Machine epsilon of ``P``'s dtype."""
    eps = _EPS.get(P.dtype)
    if eps is None:
        eps = _EPS[P.dtype] = float(np.finfo(str(P.dtype).removeprefix("torch.")).eps)
    return eps


def sigma_point_weights(n: int, alpha: float, beta: float, kappa: float) -> tuple[float, np.ndarray, np.ndarray]:
    """``(scale, Wm, Wc)``: the spread ``sqrt(n + lambda)`` and the ``2n + 1`` weights."""
    lam = alpha**2 * (n + kappa) - n
    if n + lam <= 0:
        raise ValueError(f"alpha^2 (n + kappa) must be > 0 (got alpha={alpha}, kappa={kappa}, n={n})")
    wm = np.full(2 * n + 1, 1.0 / (2.0 * (n + lam)))
    wc = wm.copy()
    wm[0] = lam / (n + lam)
    wc[0] = lam / (n + lam) + 1.0 - alpha**2 + beta
    return (n + lam) ** 0.5, wm, wc


def _safe_cholesky(P: Array) -> Array:
    L, failed = cholesky(P)
    if bool(failed.any()):
        xp = namespace(P)
        eps = _eps(P)
        jitter = eps**0.5 * xp.clip(xp.mean(_diagonal(P), axis=1), eps, None)
        L_jittered = cholesky(P + jitter[:, None, None] * eye(P, P.shape[-1]))[0]
        L = xp.where(failed[:, None, None], L_jittered, L)
    return L


class UnscentedKalmanFilter(KalmanFilter):
    """UKF over any :class:`~fkn_bench.models.base.StateSpaceModel` with a linear measurement.

    Keyword-only arguments:
        model: the state-space model (default :class:`PoseTwistModel`).
        alpha, beta, kappa: sigma-point parameters (see module docstring).
    """

    name = "ukf"

    def __init__(
        self, *, model: StateSpaceModel | None = None, alpha: float = 1.0, beta: float = 2.0, kappa: float = 0.0
    ) -> None:
        self.model = model if model is not None else PoseTwistModel()
        self.layout = self.model.layout
        self.alpha, self.beta, self.kappa = float(alpha), float(beta), float(kappa)
        self._scale, self._wm, self._wc = sigma_point_weights(self.model.state_dim, self.alpha, self.beta, self.kappa)
        self._cache: dict = {}

    def predict(self, state: FilterState, process_noise: Array, dt: float) -> FilterState:
        x, P = state.mean, state.covariance
        xp = namespace(x)
        batch, n = x.shape
        direction = self.model.null_direction(x)
        if direction is not None:
            eps = max(1e-10, 100.0 * _eps(P)) * (np.maximum.reduce(_diagonal(P), axis=1) if xp is np else xp.amax(_diagonal(P), axis=1))
            P = P + eps[:, None, None] * (direction[:, :, None] * direction[:, None, :])  # e e^T: exactly symmetric
        L = _safe_cholesky(P) * self._scale
        spread = L.swapaxes(1, 2)  # rows are the columns of L
        points = xp.concat((x[:, None, :], x[:, None, :] + spread, x[:, None, :] - spread), axis=1)
        moved = xp.reshape(self.model.predict(xp.reshape(points, (-1, n)), dt), (batch, 2 * n + 1, n))
        wm = constant(x, ("ukf-wm", id(self)), lambda: self._wm, self._cache)
        wc = constant(x, ("ukf-wc", id(self)), lambda: self._wc, self._cache)
        mean = (wm @ moved)  # (B, n): sum_p Wm_p X_p
        deviation = moved - mean[:, None, :]
        covariance = (deviation.swapaxes(1, 2) * wc) @ deviation + process_noise
        return FilterState(mean, symmetrize(covariance))  # the weighted sum is symmetric only to rounding

    def update(self, state: FilterState, z: Array, measurement_noise: Array) -> tuple[FilterState, Array, Array]:
        return linear_measurement_update(self.model, state, z, measurement_noise)
