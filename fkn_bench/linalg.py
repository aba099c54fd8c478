"""Linear-algebra helpers shared by the torch filters and the numpy code (lowest layer: no
imports from the rest of the package).

A covariance built from a product (``L L^T``, ``F P F^T + Q``, a Joseph update, a sigma-point
sum) is symmetric only to rounding: ``(A B)_ij`` and ``(A B)_ji`` are different sums of products,
and whether they round alike depends on the CPU and the BLAS (blocking, FMA, vector width).
Every covariance that leaves the function that builds it goes through :func:`symmetrize`, which
makes it symmetric bit for bit on any machine.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, TypeVar

if TYPE_CHECKING:
    import numpy as np
    import torch

__all__ = ["symmetrize"]

Matrices = TypeVar("Matrices", "np.ndarray", "torch.Tensor")


def symmetrize(M: Matrices) -> Matrices:
    """``(M + M^T) / 2`` on the last two axes of a batch of square floating-point matrices
    ``(..., k, k)`` (numpy array or torch tensor; differentiable, the input is not modified).

    The result is exactly symmetric (``a + b`` and ``b + a`` round alike, and halving is exact),
    and a matrix that is already exactly symmetric comes back unchanged.
    """
    out = M + M.swapaxes(-1, -2)
    out *= 0.5  # in place on the fresh sum: one temporary less (autograd-safe: add keeps no output)
    return out
