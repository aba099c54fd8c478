"""Linear-algebra helpers shared by the filters and the numpy code (lowest layer: no imports from
the rest of the package), and the small dispatch that lets one function run on numpy arrays
(online, one sequence) and on torch tensors (batched, differentiable).

The models and filter steps are written once against the API that numpy (2.x) and torch share
(``@``, slicing, ``xp.concat``, ``xp.stack``, ``xp.where``, ``xp.sqrt``, ``axis=``/``keepdims=``
keywords, ``swapaxes``): :func:`namespace` gives ``xp`` (the ``numpy`` or ``torch`` module) for
an array. Where torch has a fused operation the batched path relies on for its speed
(``addmm``/``baddbmm``, ``inv_ex``), a helper here dispatches to it.

A covariance built from a product (``L L^T``, ``F P F^T + Q``, a Joseph update, a sigma-point
sum) is symmetric only to rounding: ``(A B)_ij`` and ``(A B)_ji`` are different sums of products,
and whether they round alike depends on the CPU and the BLAS (blocking, FMA, vector width).
Every covariance that leaves the function that builds it goes through :func:`symmetrize`, which
makes it symmetric bit for bit on any machine.
"""

from __future__ import annotations

import operator
from types import ModuleType
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

if TYPE_CHECKING:
    import torch

__all__ = ["symmetrize", "namespace", "add_matmul", "broadcast", "divide_spd", "all_last", "dot", "sum_last", "spd_inverse", "solve_spd", "cholesky", "eye", "constant", "zeros"]

Matrices = TypeVar("Matrices", "np.ndarray", "torch.Tensor")


def namespace(x: Any) -> ModuleType:
    """``numpy`` for a numpy array, else ``torch`` (the array namespace ``xp`` of ``x``)."""
    if isinstance(x, np.ndarray):
        return np
    import torch

    return torch


def symmetrize(M: Matrices) -> Matrices:
    """``(M + M^T) / 2`` on the last two axes of a batch of square floating-point matrices
    ``(..., k, k)`` (numpy array or torch tensor; differentiable, the input is not modified).

    The result is exactly symmetric (``a + b`` and ``b + a`` round alike, and halving is exact),
    and a matrix that is already exactly symmetric comes back unchanged.
    """
    out = M + M.swapaxes(-1, -2)
    out *= 0.5  # in place on the fresh sum: one temporary less (autograd-safe: add keeps no output)
    return out


def add_matmul(C: Matrices, A: Matrices, B: Matrices) -> Matrices:
    """``C + A @ B`` (torch: the fused ``addmm``/``baddbmm``; ``C`` broadcasts)."""
    if isinstance(A, np.ndarray):
        return C + A @ B
    import torch

    if A.dim() == 2:
        return torch.addmm(C, A, B)
    if A.dim() == 3:
        return torch.baddbmm(C, A, B)
    return C + A @ B


def dot(a: np.ndarray, b: np.ndarray) -> float:
    """``a @ b`` of two short 1-D numpy vectors, summed in order on Python floats (numpy's
    dispatch costs more than the sum at 3 or 4 entries)."""
    return sum(map(operator.mul, a.tolist(), b.tolist()), 0.0)


def all_last(a: Any) -> Any:
    """``a.all(-1)`` (numpy: the ufunc reduction directly, without ``ndarray.all``'s wrapper)."""
    return np.logical_and.reduce(a, axis=-1) if isinstance(a, np.ndarray) else a.all(-1)


def sum_last(a: Any) -> Any:
    """``a.sum(-1, keepdims=True)`` (numpy: the ufunc reduction directly)."""
    return np.add.reduce(a, axis=-1, keepdims=True) if isinstance(a, np.ndarray) else a.sum(-1, keepdim=True)


def broadcast(x: Matrices, shape: tuple[int, ...]) -> Matrices:
    """``x`` broadcast to ``shape``: a view in torch (``expand``); in numpy a fresh array (faster
    than ``numpy.broadcast_to`` at the sizes of one online step)."""
    if isinstance(x, np.ndarray):
        out = np.empty(shape, dtype=x.dtype)
        out[...] = x
        return out
    return x.expand(shape)


def divide_spd(M: Matrices, S: Matrices) -> Matrices:
    """``M S^-1`` for ``M (B, n, m)`` and symmetric positive definite ``S (B, m, m)``. torch:
    one product with ``inv_ex(S)`` (no error check: no synchronisation, a batch keeps running);
    numpy: LAPACK's Cholesky solver per row (``S^-1 M^T``; one batched inverse above 64 rows),
    ``numpy.linalg.LinAlgError`` when ``S`` is not positive definite."""
    if not isinstance(S, np.ndarray):
        import torch

        return M @ torch.linalg.inv_ex(S)[0]
    if S.shape[0] == 1:  # one row (online): LAPACK directly
        return solve_spd(S[0], M[0].T).T[None]
    if S.shape[0] > 64:
        np.linalg.cholesky(S)  # raises LinAlgError where S is not positive definite
        return M @ np.linalg.inv(S)
    return np.concatenate([divide_spd(M[row : row + 1], S[row : row + 1]) for row in range(S.shape[0])])


def solve_spd(S: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``S^-1 B`` for one symmetric positive definite numpy matrix ``S (m, m)`` and ``B (m, k)``
    (LAPACK's Cholesky solver ``dposv``); ``numpy.linalg.LinAlgError`` when ``S`` is not
    positive definite."""
    _, solution, info = (_LAPACK or _lapack()).dposv(S, B, lower=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"innovation covariance is not positive definite (dposv info {info})")
    return solution


_LAPACK: Any = None


def _lapack() -> Any:
    """``scipy.linalg.lapack``, imported on first use (importing scipy is slow; the torch path
    never needs it)."""
    global _LAPACK
    if _LAPACK is None:
        from scipy.linalg import lapack

        _LAPACK = lapack
    return _LAPACK


def spd_inverse(S: Matrices) -> Matrices:
    """``S^-1`` for symmetric positive definite ``S (B, m, m)`` (see :func:`divide_spd`)."""
    return divide_spd(broadcast(eye(S, S.shape[-1]), tuple(S.shape)), S)


def cholesky(S: Matrices) -> tuple[Matrices, Any]:
    """Lower Cholesky factors of a batch ``(B, k, k)`` and a ``(B,)`` bool array, True where the
    factorisation failed (torch: ``cholesky_ex``; numpy: LAPACK per row). Failed rows hold
    garbage."""
    if isinstance(S, np.ndarray):
        lapack = _lapack()
        L = np.empty(S.shape, dtype=S.dtype)
        failed = np.zeros(S.shape[0], dtype=bool)
        for row in range(S.shape[0]):
            L[row], info = lapack.dpotrf(S[row], lower=1, clean=1)
            failed[row] = info != 0
        return L, failed
    import torch

    L, info = torch.linalg.cholesky_ex(S)
    return L, info != 0


_CONSTANTS: dict[tuple, Any] = {}


def constant(like: Any, key: Any, make: Any, cache: dict | None = None) -> Any:
    """A cached constant array in the namespace, dtype and device of ``like``: ``make()`` (a
    float64 numpy array) converted once per (namespace, dtype, device, key), in ``cache`` (an object's own dict
    for constants of that object) or a module cache bounded to 256 entries (irregular online
    intervals must not grow it)."""
    store = _CONSTANTS if cache is None else cache
    full = (type(like), like.dtype, _device(like), key)
    value = store.get(full)
    if value is None:
        if len(store) >= 256:
            store.clear()
        array = make()
        if isinstance(like, np.ndarray):
            value = array.astype(like.dtype, copy=False)
            value.flags.writeable = False
        else:
            import torch

            value = torch.from_numpy(np.array(array, dtype=np.float64)).to(device=like.device, dtype=like.dtype)
        store[full] = value
    return value


def zeros(like: Any, shape: tuple[int, ...]) -> Any:
    """Zeros of ``shape`` in the namespace and dtype of ``like`` (and, torch, on its device)."""
    return np.zeros(shape, dtype=like.dtype) if isinstance(like, np.ndarray) else like.new_zeros(shape)


def _device(like: Any) -> Any:
    """The device of a torch tensor (None for a numpy array): part of a cached constant's key."""
    return None if isinstance(like, np.ndarray) else like.device


def eye(like: Any, n: int) -> Any:
    """The ``n x n`` identity in the namespace, dtype and device of ``like`` (cached, read-only)."""
    value = _CONSTANTS.get((type(like), like.dtype, _device(like), ("eye", n)))
    return value if value is not None else constant(like, ("eye", n), lambda: np.eye(n))
