"""Training objectives through the filter recursion.

* ``supervised``: mean squared error of all 13 state components against the truth, the estimated
  quaternion compared with the true one of the same sign (FlexKalmanNet section 4.2), excluding
  the first ``loss_cut`` steps of each sequence (the paper's loss cut, 100). Its square root is
  the "13-state RMSE" the paper reports as training, validation and test loss.
* ``nll``: the innovation negative log-likelihood, which needs no ground truth (e.g.
  Abbeel et al., "Discriminative training of Kalman filters", RSS 2005; Sarkka, Bayesian
  Filtering and Smoothing, 2013, section 12.3): the mean over update steps after ``loss_cut`` of
  ``1/2 [m log 2 pi + log det S_k + nu_k^T S_k^-1 nu_k]``.
* ``gaussian-nll``: the Gaussian negative log-likelihood of the true state under the estimate and
  its reported error covariance (:func:`gaussian_nll`), for estimators that carry a covariance of
  their own (Recursive KalmanNet; Mortada et al., EUSIPCO 2025). Only a
  :class:`~fkn_bench.training.SequenceModel` that declares it in ``objectives`` trains with it.
"""

from __future__ import annotations

import math
import torch
from torch import Tensor

from fkn_bench.filters.base import FilterResult
from fkn_bench.types import Float

__all__ = ["OBJECTIVES", "OBJECTIVE_LABELS", "aligned_state_error", "state_mse", "innovation_nll", "gaussian_nll"]

OBJECTIVES: tuple[str, ...] = ("supervised", "nll")
"""The objectives of :class:`~fkn_bench.training.TrainConfig` (its subclasses may allow others)."""

OBJECTIVE_LABELS: dict[str, str] = {
    "supervised": "13-state RMSE",
    "nll": "innovation NLL per update",
    "gaussian-nll": "Gaussian NLL of the state error per step",
}
"""What the validation loss of each objective is (history, figures, artefacts)."""


def aligned_state_error(means: Float[Tensor, "... n"], truth: Float[Tensor, "... 13"]) -> Float[Tensor, "... 13"]:
    """``means - truth`` ``(..., 13)`` with the true quaternion's sign matched to the estimate
    (states augmented beyond the 13 of the truth, e.g. with inertia ratios, are compared on their
    first 13 components)."""
    dot = (means[..., :4] * truth[..., :4]).sum(-1, keepdim=True)
    q_true = torch.where(dot < 0, -truth[..., :4], truth[..., :4])
    return torch.cat((means[..., :4] - q_true, means[..., 4 : truth.shape[-1]] - truth[..., 4:]), dim=-1)


def state_mse(means: Float[Tensor, "B T n"], truth: Float[Tensor, "B T 13"], loss_cut: int) -> Float[Tensor, ""]:
    """Mean squared 13-state error over steps ``loss_cut:`` of every sequence (a scalar)."""
    if loss_cut >= means.shape[1]:
        raise ValueError(f"loss_cut {loss_cut} leaves no steps of {means.shape[1]}")
    return aligned_state_error(means[:, loss_cut:], truth[:, loss_cut:]).square().mean()


def innovation_nll(result: FilterResult, loss_cut: int) -> Tensor:
    """Mean innovation negative log-likelihood per update after ``loss_cut`` (a scalar)."""
    if result.innovations is None or result.innovation_covariances is None:
        raise ValueError("the innovation NLL needs a filter run with store_innovations=True")
    used = result.updated[:, loss_cut:]
    if not bool(used.any()):
        raise ValueError("no measurement updates after the loss cut: the NLL is undefined")
    nu = result.innovations[:, loss_cut:][used]
    S = result.innovation_covariances[:, loss_cut:][used]
    L, failed = torch.linalg.cholesky_ex(S)
    if bool(failed.any()):
        return _not_positive_definite(S)
    whitened = torch.linalg.solve_triangular(L, nu.unsqueeze(-1), upper=False).squeeze(-1)
    log_det = 2.0 * torch.log(torch.diagonal(L, dim1=-2, dim2=-1)).sum(-1)
    m = nu.shape[-1]
    return 0.5 * (m * math.log(2.0 * math.pi) + log_det + whitened.square().sum(-1)).mean()


def _not_positive_definite(covariances: Tensor) -> Tensor:
    """The NLL where a covariance is not positive definite: +inf, so that training takes it as a
    non-finite loss (the step that led there is undone, :mod:`fkn_bench.training.trainer`) and
    validation as a diverged epoch, instead of raising from the factorisation."""
    return covariances.new_tensor(math.inf)


def gaussian_nll(errors: Float[Tensor, "... k"], covariances: Float[Tensor, "... k k"]) -> Float[Tensor, ""]:
    """Mean Gaussian negative log-likelihood ``1/2 [k log 2 pi + log det P + e^T P^-1 e]`` of
    errors ``(..., k)`` under covariances ``(..., k, k)`` (a scalar); +inf where any covariance
    is not positive definite (the recursion left the physical range)."""
    L, failed = torch.linalg.cholesky_ex(covariances)
    if bool(failed.any()):
        return _not_positive_definite(covariances)
    whitened = torch.linalg.solve_triangular(L, errors.unsqueeze(-1), upper=False).squeeze(-1)
    log_det = 2.0 * torch.log(torch.diagonal(L, dim1=-2, dim2=-1)).sum(-1)
    k = errors.shape[-1]
    return 0.5 * (k * math.log(2.0 * math.pi) + log_det + whitened.square().sum(-1)).mean()
