"""Extended Kalman filter step (FlexKalmanNet eqs. 1-5), one function for numpy and torch.

Predict ``x- = f(x+)``, ``P- = F P+ F^T + Q`` with the model's analytic Jacobian ``F``; update
with gain ``K = P- H^T S^-1``, ``S = H P- H^T + R``, and the
Joseph form ``P+ = (I - K H) P- (I - K H)^T + K R K^T`` (Bucy & Joseph 1968; Simon, Optimal State
Estimation, 2006, eq. 5.19), which stays symmetric positive semi-definite for any gain. The model
then aligns, renormalises and projects (see :class:`~fkn_bench.models.pose_twist.PoseTwistModel`).
When the model measures a slice of the state (``H = [I 0]``), products with ``H`` are slices.

The step runs on torch tensors (batched, differentiable: :meth:`KalmanFilter.run`) and on numpy
arrays (the online ``step()`` of the estimators, batch 1, and the adaptive filters) through the
same code (:func:`fkn_bench.linalg.namespace`). For :class:`PoseTwistModel` torch batches of at
least :data:`STRUCTURED_MIN_BATCH` rows, :class:`ExtendedKalmanFilter` runs the same step written
for the model's structure instead (:mod:`fkn_bench.filters.structured`: equal to rounding), and
so does any CPU float64 batch, as compiled kernels (:mod:`fkn_bench.filters.kernels`).

Products such as ``F P F^T`` are symmetric only to rounding; ``predict`` and the update
symmetrise the covariance they return (:func:`fkn_bench.linalg.symmetrize`, once each), so that
every covariance leaving them is symmetric bit for bit on any machine.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from fkn_bench.filters import kernels
from fkn_bench.filters.base import FilterState, KalmanFilter
from fkn_bench.models.base import StateSpaceModel
from fkn_bench.models.pose_twist import PoseTwistModel
from fkn_bench.filters.structured import pose_predict, pose_predict_steps, pose_update
from fkn_bench.linalg import add_matmul, broadcast, constant, divide_spd, eye, namespace, solve_spd, symmetrize, zeros
from fkn_bench.types import Array

__all__ = ["ExtendedKalmanFilter", "joseph_update", "linear_measurement_update", "STRUCTURED_MIN_BATCH"]



def joseph_update(
    x: Array,
    P: Array,
    nu: Array,
    R: Array,
    *,
    H: Array | None = None,
    observed: slice | None = None,
    normalize: Callable[[Array], tuple[Array, slice | None, Array | None]] | None = None,
) -> tuple[Array, Array, Array, Array]:
    """Kalman update of ``x (B, n)``, ``P (B, n, n)`` with innovation ``nu (B, m)``.

    Either ``observed`` (``H = [I 0]`` on that slice: products with ``H`` become slices) or a
    dense ``H (m, n)`` must be given; ``R`` is ``(m, m)`` or ``(B, m, m)``. ``normalize`` maps the
    posterior mean to its manifold and returns the projection's Jacobian ``T`` (identity but for
    one diagonal block); the covariance then becomes ``(T A) P (T A)^T + (T K) R (T K)^T`` with
    ``A = I - K H``: the Joseph form followed by the projection ``T P T^T``, in one pass. Returns
    ``(x+, P+, S, K)``, ``P+`` symmetrised, and ``S`` exactly symmetric when ``P`` and ``R`` are.
    """
    xp = namespace(x)
    if xp is np:
        return _joseph_numpy(x, P, nu, R, H, observed, normalize)
    batch, n = x.shape
    if observed is not None:
        PHt = P[:, :, observed]
        S = P[:, observed, observed] + R  # a block of P plus R: exactly symmetric, as they are
    else:
        assert H is not None
        PHt = P @ H.swapaxes(0, 1)
        S = symmetrize(H @ PHt + R)
    # S is symmetric positive definite (R is): K = P H^T S^-1, one product with the inverse
    K = divide_spd(PHt, S)  # (B, n, m)
    x_post = add_matmul(x[:, :, None], K, nu[:, :, None])[:, :, 0]
    TK = K
    block = N = None
    if normalize is not None:
        x_post, block, N = normalize(x_post)
    # torch: T K and T A = T - (T K) H with T the identity but for the block N, out of place
    if block is not None and N is not None:
        TK = xp.concat((K[:, : block.start], N @ K[:, block], K[:, block.stop :]), axis=1)
    T = _projection_matrix(block, N, x, batch, n)
    TA = T - (_pad_columns(TK, observed, n) if observed is not None else TK @ H)
    P_post = add_matmul(TA @ P @ TA.swapaxes(1, 2), TK @ R, TK.swapaxes(1, 2))
    return x_post, symmetrize(P_post), S, K


def _joseph_numpy(x: np.ndarray, P: np.ndarray, nu: np.ndarray, R: np.ndarray, H: Array | None,
                  observed: slice | None, normalize: Any) -> tuple:
    """:func:`joseph_update` on numpy arrays (the online step and the adaptive filters' batches):
    ``P+ = G blockdiag(P, R) G^T`` with ``G = [T A | T K]`` and ``[A | K] = [I 0] - K [H | -I]``
    (for ``H = [I 0]`` by slices: exact). One row (online) runs on 2-D arrays with ``np.dot``
    (less dispatch per operation than 3-D ``@``, the same BLAS calls) and ``K^T = S^-1 H P`` from
    LAPACK's Cholesky solver; a batch on 3-D arrays."""
    batch, n = x.shape
    m = nu.shape[1]
    one = batch == 1
    mm = np.dot if one else np.matmul
    if one:
        P, R = P[0], (R if R.ndim == 2 else R[0])
    PHt = P[..., :, observed] if observed is not None else mm(P, H.T)
    # S is symmetric positive definite (R is); a block of P plus R is exactly symmetric, as they are
    S = P[..., observed, observed] + R if observed is not None else symmetrize(mm(H, PHt) + R)
    if one:
        Kt = solve_spd(S, P[observed] if observed is not None else PHt.T)  # (m, n); H P = (P H^T)^T
        K = Kt.T
        x_post = x + np.dot(nu, Kt)
    else:
        K = divide_spd(PHt, S)  # (B, n, m)
        x_post = x + (K @ nu[:, :, None])[:, :, 0]
    block = N = None
    if normalize is not None:
        x_post, block, N = normalize(x_post)
    G = constant(x, ("I|0", n, m), lambda: np.eye(n, n + m))
    if observed is None:
        G = G - mm(K, np.concatenate((H, -np.eye(m)), axis=1))
    else:
        G = G.copy() if one else broadcast(G, (batch, n, n + m))
        G[..., :, observed] -= K
        G[..., :, n:] = K
    if block is not None and N is not None:
        G[..., block, :] = mm(N[0] if one else N, G[..., block, :])
    D = np.zeros(P.shape[:-2] + (n + m, n + m))
    D[..., :n, :n], D[..., n:, n:] = P, R
    P_post = symmetrize(mm(mm(G, D), G.swapaxes(-1, -2)))
    return (x_post, P_post[None], S[None], K[None]) if one else (x_post, P_post, S, K)


def _pad_columns(M: Array, columns: slice, n: int) -> Array:
    """``M (B, r, m)`` placed at ``columns`` of a ``(B, r, n)`` zero matrix (``M H`` for ``H``
    selecting ``columns``)."""
    xp = namespace(M)
    batch, rows, _ = M.shape
    zero = zeros(M, (1, 1, 1))
    parts = [M]
    if columns.start:
        parts.insert(0, xp.broadcast_to(zero, (batch, rows, columns.start)))
    if columns.stop < n:
        parts.append(xp.broadcast_to(zero, (batch, rows, n - columns.stop)))
    return xp.concat(parts, axis=2) if len(parts) > 1 else M


def _projection_matrix(block: slice | None, N: Array | None, like: Array, batch: int, n: int) -> Array:
    """``T (B, n, n)``: the identity with ``N`` on the diagonal block ``block``."""
    xp = namespace(like)
    identity = eye(like, n)
    if block is None or N is None:
        return xp.broadcast_to(identity, (batch, n, n))
    rows = [_pad_columns(N, block, n)]
    if block.start:
        rows.insert(0, xp.broadcast_to(identity[: block.start], (batch, block.start, n)))
    if block.stop < n:
        rows.append(xp.broadcast_to(identity[block.stop :], (batch, n - block.stop, n)))
    return xp.concat(rows, axis=1) if len(rows) > 1 else rows[0]


def linear_measurement_update(
    model: StateSpaceModel, state: FilterState, z: Array, measurement_noise: Array
) -> tuple[FilterState, Array, Array]:
    """Kalman update for a model that measures linearly (``y = H x``), with the model's
    measurement alignment and state normalisation; shared by the EKF and the UKF. Returns the
    posterior, the innovation ``nu (B, m)`` (after alignment) and its covariance ``S``."""
    x, P = state.mean, state.covariance
    z = model.align(z, x)
    nu = z - model.measure(x)
    H = None if model.observed is not None else model.measurement_matrix(x)
    x_post, P_post, S, _ = joseph_update(x, P, nu, measurement_noise, H=H, observed=model.observed, normalize=model.normalize)
    return FilterState(x_post, P_post), nu, S


def ekf_predict(model: StateSpaceModel, state: FilterState, process_noise: Array, dt: float) -> FilterState:
    """``x- = f(x+)``, ``P- = F P+ F^T + Q`` (symmetrised); ``Q`` is ``(k, k)`` or ``(B, k, k)``."""
    mean, F = model.transition(state.mean, dt)
    if isinstance(F, np.ndarray):  # numpy: Q added in place to the fresh product
        if F.shape[0] == 1:  # one row (online): 2-D arrays and np.dot (less dispatch, same BLAS calls)
            P = np.dot(np.dot(F[0], state.covariance[0]), F[0].T)
            P += process_noise if process_noise.ndim == 2 else process_noise[0]
            return FilterState(mean, symmetrize(P)[None])
        P = F @ state.covariance @ F.swapaxes(1, 2)
        P += process_noise
    else:
        P = add_matmul(process_noise, F @ state.covariance, F.swapaxes(1, 2))
    return FilterState(mean, symmetrize(P))


STRUCTURED_MIN_BATCH = 128
"""Batch size from which the EKF of :class:`PoseTwistModel` runs the structured batch-last step
(:mod:`fkn_bench.filters.structured`) as torch operations, where its compiled kernels do not run
(not CPU float64: :func:`fkn_bench.filters.kernels.supports`; where they run, the structured
step runs at every batch size): it costs about twice as many (smaller) torch operations as the
generic step, so for small batches the generic step's fewer calls win; the two are within about
15% of each other from 96 to 256 rows (``fkn_bench/DESIGN.md``, "Performance notes")."""


class ExtendedKalmanFilter(KalmanFilter):
    """EKF over any :class:`~fkn_bench.models.base.StateSpaceModel` (default: the paper's).

    Keyword-only arguments:
        model: the state-space model (default :class:`PoseTwistModel`).

    With a model that offers ``"structured-ekf"`` (:class:`PoseTwistModel`) and torch
    batches of at least :data:`STRUCTURED_MIN_BATCH` rows, ``predict`` and ``update`` run the
    structured step (:func:`~fkn_bench.filters.structured.pose_predict`,
    :func:`~fkn_bench.filters.structured.pose_update`), and so do CPU float64 batches of any size,
    as the structured step's compiled kernels (:mod:`fkn_bench.filters.kernels`); otherwise the
    generic step.
    """

    name = "ekf"

    def __init__(self, *, model: StateSpaceModel | None = None) -> None:
        self.model = model if model is not None else PoseTwistModel()
        self.layout = self.model.layout
        self._structured = "structured-ekf" in self.model.offers

    def _structured_step(self, state: FilterState) -> bool:
        """Whether this step runs :mod:`fkn_bench.filters.structured` (the pose-twist model's own
        step, torch, at least :data:`STRUCTURED_MIN_BATCH` rows) rather than the generic one."""
        return self._structured and not isinstance(state.mean, np.ndarray) and state.mean.shape[0] >= STRUCTURED_MIN_BATCH

    def _structured_for(self, state: FilterState, noise: Array) -> bool:
        """Whether this step runs the structured step (:mod:`fkn_bench.filters.structured`):
        from :data:`STRUCTURED_MIN_BATCH` rows, and at any batch size where its compiled kernels
        run (:func:`fkn_bench.filters.kernels.supports`: one call per step, which beats the
        generic step's batched products at every batch size)."""
        return self._structured_step(state) or (
            self._structured and not isinstance(state.mean, np.ndarray)
            and kernels.supports(state.mean, state.covariance, noise)
        )

    def predict(self, state: FilterState, process_noise: Array, dt: float) -> FilterState:
        if self._structured_for(state, process_noise):
            return pose_predict(state, process_noise, dt)
        return ekf_predict(self.model, state, process_noise, dt)

    def predict_steps(
        self, state: FilterState, process_noise: Array, dt: float, count: int, *, per_step: bool = False,
        store_covariances: bool = True,
    ) -> tuple[Array, Array | None, FilterState]:
        """:meth:`KalmanFilter.predict_steps`, in one call of the compiled kernels where they run
        (:func:`~fkn_bench.filters.structured.pose_predict_steps`)."""
        if self._structured and kernels.supports(state.mean, state.covariance, process_noise):
            return pose_predict_steps(state, process_noise, dt, count, per_step=per_step, store_covariances=store_covariances)
        return super().predict_steps(state, process_noise, dt, count, per_step=per_step, store_covariances=store_covariances)

    def update(self, state: FilterState, z: Array, measurement_noise: Array) -> tuple[FilterState, Array, Array]:
        if self._structured_for(state, measurement_noise):
            return pose_update(self.model, state, z, measurement_noise)
        return linear_measurement_update(self.model, state, z, measurement_noise)
