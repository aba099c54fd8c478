"""Cholesky-KalmanNet: Split-KalmanNet with covariances positive definite by construction.

M. Ko and A. Shafieezadeh, "Cholesky-KalmanNet: Model-Based Deep Learning with Positive Definite
Error Covariance Structure", IEEE Signal Processing Letters, 2025 (reference code
RAMSIS-Lab/ckn-spl-public). The filter is Split-KalmanNet's (:mod:`fkn_bench.kalmannet.split`:
the same two branches, features and update ``x_t|t = x_t|t-1 [+] K_t dy_t``), but each branch
outputs the lower-triangular Cholesky factor of its covariance, so that both are symmetric
positive definite, the gain is a Kalman gain of them, and the error covariance can be trained and
reported as it is.

Learned and derived, with shapes (``n'``, ``m'`` the tangent dimensions: 12 and 6 on the pose
model), frames and units as Split-KalmanNet's (error ``[dtheta, dr, dw, dv]`` in rad, m, rad/s,
m/s, world frame; ``H = [I6 0]``; ``C_P``, ``C_S`` the Cholesky factors of the reference
covariances ``P_ref = diag(p0^2)`` and ``S_ref = H P_ref H^T / g``):

* learned: the state branch's ``n' (n' + 1) / 2`` outputs fill a lower-triangular ``L~_P`` (its
  diagonal through a softplus), and the prior error covariance is ``P_t|t-1 = (C_P L~_P) (C_P
  L~_P)^T + floor^2 I``; the measurement branch's ``m' (m' + 1) / 2`` outputs likewise give the
  innovation covariance ``S_t = (C_S L~_S) (C_S L~_S)^T + floor^2 I``. The output layers start
  near ``L~ = I`` (their bias ``softplus^-1(1)`` on the diagonal and zero below it, their weights
  PyTorch's times ``output_scale``), so the gain starts near ``g G`` (``g`` the ``initial_gain``,
  ``G`` the observed gain) and ``P_t|t-1`` near ``P_ref``.
* learned: the diagonal process noise ``Q = diag(s^2)`` per prediction step (``s`` from the
  reference ``q``), through which the covariance reported between measurements grows.
* derived: the gain ``K_t = P_t|t-1 H^T S_t^-1`` (a linear solve with the SPD ``S_t``) and the
  posterior error covariance by the Joseph form, ``P_t|t = (I - K H) P_t|t-1 (I - K H)^T + K R
  K^T + floor^2 I`` (the reference code's, with its model's ``R``; here the stated ``R``: the
  multiplicative EKF's manual tuning on the pose model, 0.2 rad and 0.1 m, the model's layout on
  a Euclidean one), positive definite for any ``K`` because ``P_t|t-1`` is; between measurements
  ``P = F P F^T + Q`` (``F`` the multiplicative EKF's error transition, the EKF's Jacobian on a
  Euclidean model). This is the covariance the estimator reports, the NEES columns score, the
  gate tests (``S = H P H^T + R`` at the prediction) and the Gaussian NLL trains.

Training: ``objective = "gaussian-nll"`` (default), the mean Gaussian negative log-likelihood of
the true state's error under ``N(x_t|t, P_t|t)`` at every step after ``loss_cut``, or
``"supervised"``, the MSE. The reference code's loss is ``0.95 MSE + 0.05 mean |e e^T -
P_t|t|`` (element-wise, a moment match of the covariance); the NLL fits mean and covariance with
the pipeline's objective for learned covariances (Recursive KalmanNet's), and its scale term
``log det P`` keeps the covariance from the trivial fit that the absolute-value match allows
where errors are small.

Other deviations, as Split-KalmanNet's (inputs without the constant Jacobian and zero
linearisation error, whitened and clipped; one GRU layer per branch; joint Adam steps instead of
the reference code's alternating optimisers; the gate and the lost-track rule where the filter
estimates on the pose tangent space): the reference code's diagonal is ``|.| + 1e-8``, here a
softplus with ``floor^2 I`` added, which keeps the gradient of a factor entry that crosses zero.
"""

from __future__ import annotations

import torch
from torch import Tensor
from torch.nn import functional

from fkn_bench.kalmannet.recursive import _inverse_softplus
from fkn_bench.kalmannet.split import SplitKalmanNet
from fkn_bench.linalg import symmetrize

__all__ = ["CholeskyKalmanNet", "lower_triangular"]


def lower_triangular(raw: Tensor, k: int) -> Tensor:
    """The lower-triangular ``(B, k, k)`` matrix of ``raw (B, k (k + 1) / 2)`` (row-major lower
    triangle), its diagonal through a softplus (positive)."""
    rows, cols = torch.tril_indices(k, k, device=raw.device)
    values = torch.where(rows == cols, functional.softplus(raw), raw)
    L = raw.new_zeros(raw.shape[0], k, k)
    L[:, rows, cols] = values
    return L


class CholeskyKalmanNet(SplitKalmanNet):
    """Cholesky-KalmanNet on a state-space model (see module docstring); the arguments are
    :class:`~fkn_bench.kalmannet.split.SplitKalmanNet`'s."""

    objectives = ("gaussian-nll", "supervised")
    architecture = "Cholesky-KalmanNet (Ko & Shafieezadeh, IEEE SPL 2025)"
    covariance_is_trained = True

    def branch_outputs(self, k: int) -> int:
        """Outputs of a branch for a ``k x k`` covariance: its Cholesky factor's ``k (k + 1) / 2`` entries."""
        return k * (k + 1) // 2

    def output_bias(self, k: int) -> Tensor:
        """The output layer's bias: ``softplus^-1(1)`` on the factor's diagonal, zero below it (``L~ = I``)."""
        rows, cols = torch.tril_indices(k, k)
        return torch.where(rows == cols, _inverse_softplus(1.0), 0.0).to(torch.float64)

    def prior_and_gain(self, state_raw: Tensor, measurement_raw: Tensor) -> tuple[Tensor, Tensor]:
        """``(P_t|t-1 (B, n', n'), K (B, n', m'))``: the prior error covariance from its learned
        factor and the Kalman gain ``P H^T S^-1`` with the learned innovation covariance."""
        floor = self.std_floor**2
        L_P = self.state_root.to(state_raw) @ lower_triangular(state_raw, self.n)
        L_S = self.measurement_root.to(state_raw) @ lower_triangular(measurement_raw, self.m)
        P = symmetrize(L_P @ L_P.transpose(1, 2)) + floor * torch.eye(self.n, dtype=state_raw.dtype, device=state_raw.device)
        S = symmetrize(L_S @ L_S.transpose(1, 2)) + floor * torch.eye(self.m, dtype=state_raw.dtype, device=state_raw.device)
        HP = self.H.to(state_raw) @ P
        return P, torch.linalg.solve(S, HP).transpose(1, 2)  # (S^-1 H P)^T = P H^T S^-1 (P, S symmetric)
