"""Extended Kalman filter, batched and differentiable (FlexKalmanNet eqs. 1-5).

Predict ``x- = f(x+)``, ``P- = F P+ F^T + Q`` with the model's analytic Jacobian ``F``; update
with gain ``K = P- H^T S^-1``, ``S = H P- H^T + R``, and the
Joseph form ``P+ = (I - K H) P- (I - K H)^T + K R K^T`` (Bucy & Joseph 1968; Simon, Optimal State
Estimation, 2006, eq. 5.19), which stays symmetric positive semi-definite for any gain. The model
then aligns, renormalises and projects (see :class:`~fkn_bench.filters.models.PoseTwistModel`).
When the model measures a slice of the state (``H = [I 0]``), products with ``H`` are slices.

Products such as ``F P F^T`` are symmetric only to rounding; ``predict`` and the update
symmetrise the covariance they return (:func:`fkn_bench.linalg.symmetrize`, once each), so that
every covariance leaving them is symmetric bit for bit on any machine.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor

from fkn_bench.filters.base import FilterState, KalmanFilter
from fkn_bench.filters.models import PoseTwistModel, StateSpaceModel
from fkn_bench.linalg import symmetrize

__all__ = ["ExtendedKalmanFilter", "joseph_update", "linear_measurement_update"]


def joseph_update(
    x: Tensor,
    P: Tensor,
    nu: Tensor,
    R: Tensor,
    *,
    H: Tensor | None = None,
    observed: slice | None = None,
    normalize: Callable[[Tensor], tuple[Tensor, slice | None, Tensor | None]] | None = None,
) -> tuple[Tensor, Tensor, Tensor]:
    """Kalman update of ``x (B, n)``, ``P (B, n, n)`` with innovation ``nu (B, m)``.

    Either ``observed`` (``H = [I 0]`` on that slice: products with ``H`` become slices) or a
    dense ``H (m, n)`` must be given. ``normalize`` maps the posterior mean to its manifold and
    returns the projection's Jacobian ``T`` (identity but for one diagonal block); the covariance
    then becomes ``(T A) P (T A)^T + (T K) R (T K)^T`` with ``A = I - K H``: the Joseph form
    followed by the projection ``T P T^T``, in one pass. Returns ``(x+, P+, S)``, ``P+``
    symmetrised, and ``S`` exactly symmetric when ``P`` and ``R`` are.
    """
    batch, n = x.shape
    if observed is not None:
        PHt = P[:, :, observed]
        S = P[:, observed, observed] + R  # a block of P plus R: exactly symmetric, as they are
    else:
        assert H is not None
        PHt = P @ H.T
        S = symmetrize(H @ PHt + R)
    # S is symmetric positive definite (R is); its inverse gives K with one batched product
    K = PHt @ torch.linalg.inv_ex(S)[0]  # (B, n, m)
    x_post = torch.baddbmm(x.unsqueeze(-1), K, nu.unsqueeze(-1)).squeeze(-1)
    TK = K
    block = N = None
    if normalize is not None:
        x_post, block, N = normalize(x_post)
        if block is not None and N is not None:
            TK = torch.cat((K[:, : block.start], N @ K[:, block], K[:, block.stop :]), dim=1)
    # T A = T - (T K) H with T the identity but for the block N
    T = _projection_matrix(block, N, batch, n, x.dtype)
    if observed is not None:
        TA = T - _pad_columns(TK, observed, n)
    else:
        TA = T - TK @ H
    P_post = torch.baddbmm(TA @ P @ TA.transpose(1, 2), TK @ R.expand(batch, -1, -1), TK.transpose(1, 2))
    return x_post, symmetrize(P_post), S


def _pad_columns(M: Tensor, columns: slice, n: int) -> Tensor:
    """``M (B, r, m)`` placed at ``columns`` of a ``(B, r, n)`` zero matrix (``M H`` for ``H``
    selecting ``columns``)."""
    batch, rows, _ = M.shape
    parts = [M]
    if columns.start:
        parts.insert(0, M.new_zeros(()).expand(batch, rows, columns.start))
    if columns.stop < n:
        parts.append(M.new_zeros(()).expand(batch, rows, n - columns.stop))
    return torch.cat(parts, dim=2) if len(parts) > 1 else M


def _projection_matrix(block: slice | None, N: Tensor | None, batch: int, n: int, dtype: torch.dtype) -> Tensor:
    """``T (B, n, n)``: the identity with ``N`` on the diagonal block ``block``."""
    eye = _eye(n, dtype)
    if block is None or N is None:
        return eye.expand(batch, n, n)
    rows = [_pad_columns(N, block, n)]
    if block.start:
        rows.insert(0, eye[: block.start].expand(batch, -1, -1))
    if block.stop < n:
        rows.append(eye[block.stop :].expand(batch, -1, -1))
    return torch.cat(rows, dim=1) if len(rows) > 1 else rows[0]


_EYES: dict[tuple[int, torch.dtype], Tensor] = {}


def _eye(n: int, dtype: torch.dtype) -> Tensor:
    key = (n, dtype)
    if key not in _EYES:
        _EYES[key] = torch.eye(n, dtype=dtype)
    return _EYES[key]


class ExtendedKalmanFilter(KalmanFilter):
    """EKF over any :class:`~fkn_bench.filters.models.StateSpaceModel` (default: the paper's).

    Keyword-only arguments:
        model: the state-space model (default :class:`PoseTwistModel`).
    """

    name = "ekf"

    def __init__(self, *, model: StateSpaceModel | None = None) -> None:
        self.model = model if model is not None else PoseTwistModel()
        self.layout = self.model.layout

    def predict(self, state: FilterState, process_noise: Tensor, dt: float) -> FilterState:
        mean, F = self.model.transition(state.mean, dt)
        FP = F @ state.covariance
        Q = process_noise.expand(FP.shape[0], -1, -1)
        return FilterState(mean, symmetrize(torch.baddbmm(Q, FP, F.transpose(1, 2))))

    def update(self, state: FilterState, z: Tensor, measurement_noise: Tensor) -> tuple[FilterState, Tensor, Tensor]:
        return linear_measurement_update(self.model, state, z, measurement_noise)


def linear_measurement_update(
    model: StateSpaceModel, state: FilterState, z: Tensor, measurement_noise: Tensor
) -> tuple[FilterState, Tensor, Tensor]:
    """Kalman update for a model that measures linearly (``y = H x``), with the model's
    measurement alignment and state normalisation; shared by the EKF and the UKF."""
    x, P = state.mean, state.covariance
    z = model.align(z, x)
    if model.observed is not None:
        nu = z - x[:, model.observed]
        x_post, P_post, S = joseph_update(x, P, nu, measurement_noise, observed=model.observed, normalize=model.normalize)
    else:
        H = model.H.to(x.dtype)
        nu = z - x @ H.T
        x_post, P_post, S = joseph_update(x, P, nu, measurement_noise, H=H, normalize=model.normalize)
    return FilterState(x_post, P_post), nu, S
