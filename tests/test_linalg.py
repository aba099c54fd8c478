"""fkn_bench.linalg: symmetrize gives exactly symmetric matrices, for numpy and torch alike."""

from __future__ import annotations

import numpy as np
import torch

from fkn_bench.linalg import symmetrize


def test_numpy_batch_is_exactly_symmetric_and_input_untouched() -> None:
    rng = np.random.default_rng(0)
    M = rng.standard_normal((2, 3, 5, 5))
    before = M.copy()
    S = symmetrize(M)
    assert S.shape == M.shape
    np.testing.assert_array_equal(S, np.swapaxes(S, -1, -2))
    np.testing.assert_array_equal(S, 0.5 * (M + np.swapaxes(M, -1, -2)))
    np.testing.assert_array_equal(M, before)


def test_torch_batch_is_exactly_symmetric_and_differentiable() -> None:
    generator = torch.Generator().manual_seed(0)
    M = torch.randn(4, 6, 6, generator=generator, dtype=torch.float64, requires_grad=True)
    S = symmetrize(M)
    assert torch.equal(S, S.transpose(-1, -2))
    assert torch.equal(S, 0.5 * (M + M.transpose(-1, -2)))
    weights = torch.randn(6, 6, generator=generator, dtype=torch.float64)
    (S * weights).sum().backward()
    assert M.grad is not None
    torch.testing.assert_close(M.grad, (0.5 * (weights + weights.T)).expand(4, 6, 6), rtol=0, atol=0)


def test_symmetric_input_comes_back_unchanged() -> None:
    rng = np.random.default_rng(1)
    A = rng.standard_normal((3, 4, 4))
    P = A + np.swapaxes(A, -1, -2)  # exactly symmetric
    np.testing.assert_array_equal(symmetrize(P), P)
    T = torch.from_numpy(P)
    assert torch.equal(symmetrize(T), T)


def test_product_of_a_factor_with_its_transpose() -> None:
    """``L L^T`` from a BLAS product may differ from its transpose in the last bit (CPU
    dependent); symmetrised it never does."""
    generator = torch.Generator().manual_seed(2)
    L = torch.randn(64, 7, 7, generator=generator, dtype=torch.float64).tril()
    P = symmetrize(L @ L.transpose(-1, -2))
    assert torch.equal(P, P.transpose(-1, -2))
    torch.testing.assert_close(P, L @ L.transpose(-1, -2), rtol=1e-15, atol=1e-15)
