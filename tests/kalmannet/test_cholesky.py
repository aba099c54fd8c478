"""Cholesky-KalmanNet's covariances (:mod:`fkn_bench.kalmannet.cholesky`): the learned factors
give symmetric positive definite ``P`` and ``S`` and the Kalman gain ``P H^T S^-1`` for any
branch output, however large; the estimator-level checks are ``test_split.py``'s (both peers)."""

from __future__ import annotations

import numpy as np
import torch

from fkn_bench.kalmannet import CholeskyKalmanNetConfig, build_cholesky_model
from fkn_bench.kalmannet.cholesky import lower_triangular


def test_lower_triangular_has_a_positive_diagonal() -> None:
    raw = torch.tensor([[-30.0, 2.0, -3.0, 0.0, 4.0, -5.0]], dtype=torch.float64)
    L = lower_triangular(raw, 3)[0]
    assert torch.equal(L, torch.tril(L)) and bool((L.diagonal() > 0).all())
    assert L[1, 0] == 2.0 and L[2, 0] == 0.0 and L[2, 1] == 4.0


def test_any_output_gives_spd_covariances_and_their_kalman_gain() -> None:
    net = build_cholesky_model(CholeskyKalmanNetConfig(in_mult=2, hidden_mult=1, out_mult=1))
    generator = torch.Generator().manual_seed(0)
    for scale in (1e-3, 1.0, 30.0):
        state_raw = scale * torch.randn(4, 78, generator=generator, dtype=torch.float64)
        measurement_raw = scale * torch.randn(4, 21, generator=generator, dtype=torch.float64)
        P, K = net.prior_and_gain(state_raw, measurement_raw)
        assert torch.equal(P, P.transpose(1, 2)) and bool((torch.linalg.eigvalsh(P) >= 0.99e-8).all())
        L_S = net.measurement_root @ lower_triangular(measurement_raw, 6)
        S = L_S @ L_S.transpose(1, 2) + 1e-8 * torch.eye(6, dtype=torch.float64)
        assert bool((torch.linalg.eigvalsh(S) > 0).all())
        residual = K @ S - P @ net.H.T  # K S = P H^T (a linear solve: relative to the magnitudes)
        assert float(residual.abs().max()) <= 1e-9 * float((K.abs() @ S.abs()).max())
