"""The training objectives: sign-aligned state MSE with a loss cut, and the innovation NLL."""

from __future__ import annotations

import math

import pytest
import torch

from fkn_bench.filters import make_filter
from fkn_bench.training.objectives import aligned_state_error, innovation_nll, state_mse


def test_state_error_is_sign_safe() -> None:
    truth = torch.zeros(1, 3, 13, dtype=torch.float64)
    truth[..., 0] = 1.0
    estimate = truth.clone()
    estimate[..., :4] *= -1.0  # same attitude
    # exact: after sign alignment the operands are equal, and x - x = 0
    assert torch.equal(aligned_state_error(estimate, truth), torch.zeros_like(truth))


def test_state_mse_excludes_the_loss_cut() -> None:
    truth = torch.zeros(2, 10, 13, dtype=torch.float64)
    estimate = truth.clone()
    estimate[:, :4, 5] = 100.0  # huge errors only before the cut
    estimate[:, 4:, 5] = 1.0
    assert state_mse(estimate, truth, loss_cut=4).item() == pytest.approx(1.0 / 13.0)
    with pytest.raises(ValueError, match="leaves no steps"):
        state_mse(estimate, truth, loss_cut=10)


def test_innovation_nll_matches_the_gaussian_formula() -> None:
    variant = make_filter("ekf")
    z = torch.zeros(1, 3, 7, dtype=torch.float64)
    z[..., 0] = 1.0
    z[0, 1, 4] = 0.3
    z[0, 2, 5] = -0.2
    mask = torch.ones(1, 3, dtype=torch.bool)
    result = variant.run(variant.layout.default_noise(), z, mask, dt=0.1)
    nll = innovation_nll(result, loss_cut=0)
    used = result.updated[0]
    expected = []
    for t in torch.nonzero(used).flatten().tolist():
        nu, S = result.innovations[0, t], result.innovation_covariances[0, t]
        quad = nu @ torch.linalg.solve(S, nu)
        expected.append(0.5 * (7 * math.log(2 * math.pi) + torch.logdet(S) + quad))
    assert nll.item() == pytest.approx(torch.stack(expected).mean().item(), rel=1e-12)
    with pytest.raises(ValueError, match="no measurement updates"):
        innovation_nll(result, loss_cut=3)


def test_gaussian_nll_is_infinite_where_a_covariance_is_not_positive_definite() -> None:
    from fkn_bench.training.objectives import gaussian_nll

    errors = torch.tensor([[0.1, -0.2], [0.3, 0.0]], dtype=torch.float64)
    covariances = torch.stack([torch.eye(2, dtype=torch.float64), torch.diag(torch.tensor([2.0, 0.5], dtype=torch.float64))])
    expected = torch.distributions.MultivariateNormal(torch.zeros(2, dtype=torch.float64), covariances).log_prob(errors)
    assert float(gaussian_nll(errors, covariances)) == pytest.approx(-float(expected.mean()), rel=1e-12)
    broken = covariances.clone()
    broken[1] = torch.tensor([[1.0, 2.0], [2.0, 1.0]])  # indefinite: a recursion that left the physical range
    assert gaussian_nll(errors, broken).item() == math.inf  # a non-finite loss the trainer undoes, not an exception
