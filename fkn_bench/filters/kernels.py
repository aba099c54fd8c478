"""Compiled CPU kernels (numba) of the pose-twist EKF prediction, forward and backward.

:func:`fkn_bench.filters.structured.pose_predict` forms ``x- = f(x)``, ``P- = F P F^T + Q`` from the
transition's structure (``F = I + Delta``, see that module) as about thirty torch operations on
batch-last ``(13, 13, B)`` blocks; at B = 64 (a training batch) each costs more in dispatch than in
arithmetic, and at B = 1024 each makes its own pass over memory. These kernels do the same
arithmetic, in the same order of operations per entry (equal to rounding: ``tests/filters/
test_kernels.py``), in one pass over the batch each, with the batch innermost so that the
compiler vectorises it. They run on CPU tensors of float32 or float64 (C-contiguous batch-last
arrays: :func:`predict` and :func:`predict_backward` make them so); anything else (a GPU, another
dtype) takes the torch operations, which stay the reference implementation.

Measured on the 2-core AMD EPYC CI machine, one thread (``fkn-bench bench run -k predict`` times
both on any machine): the prediction's forward pass 2.2x faster than the torch operations at
B = 1024 and 8x at B = 64; its backward pass 3.4x and 18x.

Compilation (``numba.njit``, ``cache=True``) happens on first use, a few seconds per dtype, and is
cached on disk beside this file (or in numba's user cache directory where that is read-only);
:data:`ENABLED` switches the kernels off (the torch operations then run everywhere), which is how
the tests compare the two.
"""

from __future__ import annotations

import functools
import os
from typing import Any

import numpy as np
import torch
from torch import Tensor

__all__ = ["ENABLED", "supports", "predict", "predict_backward"]

ENABLED: bool = os.environ.get("FKN_BENCH_KERNELS", "1") != "0"
"""Whether :func:`supports` may say yes (environment ``FKN_BENCH_KERNELS=0`` turns the kernels
off at import; tests set the attribute)."""

_DTYPES = (torch.float64, torch.float32)
_U = np.array([0, 1, 2, 3, 7, 8, 9], dtype=np.int64)
"""The state components ``[q, w]`` on which the quaternion rows of ``F`` depend."""


@functools.cache
def _numba() -> Any:
    """The numba module, or None when it cannot be imported (the torch operations then run)."""
    try:
        import numba
    except ImportError:  # pragma: no cover - numba is a dependency; a broken install falls back
        return None
    return numba


def supports(*tensors: Tensor) -> bool:
    """Whether the kernels can run on these tensors: CPU, float32 or float64, one dtype, kernels
    enabled and numba importable."""
    if not ENABLED:
        return False
    dtype = tensors[0].dtype
    for t in tensors:  # (a loop, not any() over a generator: this runs at every step)
        if not t.is_cpu or t.dtype is not dtype:
            return False
    return dtype in _DTYPES and _numba() is not None


@functools.cache
def _g_sparsity(dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``(source, coefficient)`` per entry ``r`` of ``Ghat`` (4 x 7, row-major): ``Ghat[r] =
    coefficient[r] * x[source[r]]`` (each entry of ``[dt/2 Omega(w) | dt/2 Theta(q)]`` is one
    signed state component or zero: :func:`fkn_bench.filters.structured._g_basis`)."""
    from fkn_bench.filters.structured import _g_basis

    basis = _g_basis(dt)
    source, coefficient = np.zeros(28, dtype=np.int64), np.zeros(28)
    for r in range(28):
        (nonzero,) = np.nonzero(basis[r])
        if nonzero.size > 1:  # pragma: no cover - a property of the model, checked here once
            raise AssertionError("each entry of the pose-twist model's Ghat is one state component")
        if nonzero.size:
            source[r], coefficient[r] = nonzero[0], basis[r, nonzero[0]]
    return source, coefficient


def _predict_forward_kernel(x, P, Q, dt, source, coefficient, x_out, P_out, Ghat, D, corner):  # type: ignore[no-untyped-def]
    """Batch-last prediction (:func:`fkn_bench.filters.structured._predict_forward`, same
    operations per entry): ``x (13, B)``, ``P (13, 13, B)``, ``Q (B or 1, 13, 13)`` (batch-first,
    as noise parameters are stored: read in place, not copied batch-last at every step) ->
    ``x_out``, ``P_out``, ``Ghat (4, 7, B)``; ``D (7, 13, B)`` and ``corner (7, 4, B)`` are
    scratch."""
    B = x.shape[1]
    for r in range(28):
        i, k, j, c = r // 7, r % 7, source[r], coefficient[r]
        for b in range(B):
            Ghat[i, k, b] = c * x[j, b]
    for i in range(4):  # q- = q + Ghat[:, q] q
        for b in range(B):
            x_out[i, b] = Ghat[i, 0, b] * x[0, b]
        for k in range(1, 4):
            for b in range(B):
                x_out[i, b] += Ghat[i, k, b] * x[k, b]
        for b in range(B):
            x_out[i, b] += x[i, b]
    for i in range(3):  # r- = r + dt v; w, v unchanged
        for b in range(B):
            x_out[4 + i, b] = x[4 + i, b] + dt * x[10 + i, b]
    for i in range(7, 13):
        for b in range(B):
            x_out[i, b] = x[i, b]
    for i in range(4):  # D[q] = Ghat P[u]
        for j in range(13):
            for b in range(B):
                s = Ghat[i, 0, b] * P[0, j, b]
                s += Ghat[i, 1, b] * P[1, j, b]
                s += Ghat[i, 2, b] * P[2, j, b]
                s += Ghat[i, 3, b] * P[3, j, b]
                s += Ghat[i, 4, b] * P[7, j, b]
                s += Ghat[i, 5, b] * P[8, j, b]
                s += Ghat[i, 6, b] * P[9, j, b]
                D[i, j, b] = s
    for i in range(3):  # D[r] = dt P[v]
        for j in range(13):
            for b in range(B):
                D[4 + i, j, b] = P[10 + i, j, b] * dt
    for a in range(7):  # corner = D[:, u] Ghat^T = (Delta P Delta^T)[q r, q]
        for i in range(4):
            for b in range(B):
                s = D[a, 0, b] * Ghat[i, 0, b]
                s += D[a, 1, b] * Ghat[i, 1, b]
                s += D[a, 2, b] * Ghat[i, 2, b]
                s += D[a, 3, b] * Ghat[i, 3, b]
                s += D[a, 7, b] * Ghat[i, 4, b]
                s += D[a, 8, b] * Ghat[i, 5, b]
                s += D[a, 9, b] * Ghat[i, 6, b]
                corner[a, i, b] = s
    for a in range(7):  # N = D + corner / 2 (columns q) + dt/2 D[:, v] (columns r), in D
        for i in range(4):
            for b in range(B):
                D[a, i, b] += corner[a, i, b] * 0.5
        for i in range(3):
            for b in range(B):
                D[a, 4 + i, b] += D[a, 10 + i, b] * (0.5 * dt)
    per_row_q = Q.shape[0] != 1
    for i in range(13):  # P- = (P + sym(Q)) + N + N^T on their blocks: exactly symmetric
        for j in range(13):
            if per_row_q:
                for b in range(B):
                    P_out[i, j, b] = P[i, j, b] + (Q[b, i, j] + Q[b, j, i]) * 0.5
            else:
                q = (Q[0, i, j] + Q[0, j, i]) * 0.5
                for b in range(B):
                    P_out[i, j, b] = P[i, j, b] + q
            if i < 7 and j < 7:
                for b in range(B):
                    P_out[i, j, b] += D[i, j, b] + D[j, i, b]
            elif i < 7:
                for b in range(B):
                    P_out[i, j, b] += D[i, j, b]
            elif j < 7:
                for b in range(B):
                    P_out[i, j, b] += D[j, i, b]

def _predict_backward_kernel(x, P, Ghat, g_mean, g_P, dt, source, coefficient, dx, X, dQ, Xu, dG):  # type: ignore[no-untyped-def]
    """The backward pass of :class:`fkn_bench.filters.structured._PosePredict` (same
    operations per entry): ``x (13, B)``, ``P (13, 13, B)``, ``Ghat (4, 7, B)``, the output
    gradients ``g_mean (13, B)``, ``g_P (13, 13, B)`` -> ``dx (B, 13)``, ``X (13, 13, B)``
    (``dL/dP``) and, when ``dQ`` is ``(B, 13, 13)`` (batch-first, as ``Q``), ``dQ = sym(g_P)``
    (a broadcast ``Q``'s sum over the batch is the caller's); ``Xu (7, 13, B)`` and
    ``dG (4, 7, B)`` are scratch."""
    B = x.shape[1]
    per_row_q = dQ.shape[0] == B and dQ.shape[0] != 1
    for i in range(13):  # X = Gbar = sym(g_P)
        for j in range(13):
            for b in range(B):
                X[i, j, b] = (g_P[i, j, b] + g_P[j, i, b]) * 0.5
            if per_row_q:
                for b in range(B):
                    dQ[b, i, j] = X[i, j, b]
    for k in range(7):  # Xu = G^T Gbar[q] with G = Ghat + [I 0]
        for j in range(13):
            for b in range(B):
                s = Ghat[0, k, b] * X[0, j, b]
                s += Ghat[1, k, b] * X[1, j, b]
                s += Ghat[2, k, b] * X[2, j, b]
                s += Ghat[3, k, b] * X[3, j, b]
                if k < 4:
                    s += X[k, j, b]
                Xu[k, j, b] = s
    for j in range(13):  # X = F^T Gbar: rows q = Xu[q], w += Xu[w], v += dt X[r]
        for i in range(4):
            for b in range(B):
                X[i, j, b] = Xu[i, j, b]
        for i in range(3):
            for b in range(B):
                X[7 + i, j, b] += Xu[4 + i, j, b]
            for b in range(B):
                X[10 + i, j, b] += X[4 + i, j, b] * dt
    U = (0, 1, 2, 3, 7, 8, 9)
    for i in range(4):  # dG = 2 X[:, q]^T P[:, u] + (g_q x_q^T on the columns q)
        for k in range(7):
            u = U[k]
            for b in range(B):
                dG[i, k, b] = X[0, i, b] * P[0, u, b]
            for a in range(1, 13):
                for b in range(B):
                    dG[i, k, b] += X[a, i, b] * P[a, u, b]
            for b in range(B):
                dG[i, k, b] *= 2.0
            if k < 4:
                for b in range(B):
                    dG[i, k, b] += g_mean[i, b] * x[k, b]
    for b in range(B):  # dx = f's linear part + C^T dG (Ghat = C x)
        for k in range(4):
            s = 0.0
            for i in range(4):
                s += (Ghat[i, k, b] + (1.0 if i == k else 0.0)) * g_mean[i, b]
            dx[b, k] = s
        for i in range(3):
            dx[b, 4 + i] = g_mean[4 + i, b]
            dx[b, 7 + i] = g_mean[7 + i, b]
            dx[b, 10 + i] = g_mean[10 + i, b] + g_mean[4 + i, b] * dt
        for r in range(28):
            if coefficient[r] != 0.0:
                dx[b, source[r]] += coefficient[r] * dG[r // 7, r % 7, b]
    for a in range(13):  # dP = X F: columns q = X[:, q] G[:, q], w += X[:, q] G[:, w], v += dt X[:, r]
        for k in range(7):
            for b in range(B):
                s = X[a, 0, b] * Ghat[0, k, b]
                s += X[a, 1, b] * Ghat[1, k, b]
                s += X[a, 2, b] * Ghat[2, k, b]
                s += X[a, 3, b] * Ghat[3, k, b]
                if k < 4:
                    s += X[a, k, b]
                Xu[k, a, b] = s
        for k in range(4):
            for b in range(B):
                X[a, k, b] = Xu[k, a, b]
        for k in range(3):
            for b in range(B):
                X[a, 7 + k, b] += Xu[4 + k, a, b]
            for b in range(B):
                X[a, 10 + k, b] += X[a, 4 + k, b] * dt


@functools.cache
def _kernels() -> dict[str, Any]:
    """The compiled kernels (compiled once per process and dtype on first call; numba's on-disk
    cache makes that a load after the first process)."""
    numba = _numba()
    try:
        jit = numba.njit(cache=True, nogil=True, boundscheck=False)
        return {"predict_forward": jit(_predict_forward_kernel), "predict_backward": jit(_predict_backward_kernel)}
    except RuntimeError:  # pragma: no cover - no writable cache directory: compile in every process
        jit = numba.njit(cache=False, nogil=True, boundscheck=False)
        return {"predict_forward": jit(_predict_forward_kernel), "predict_backward": jit(_predict_backward_kernel)}



def _array(t: Tensor) -> np.ndarray:
    """A C-contiguous numpy view of ``t`` (copied first when it is not contiguous)."""
    return t.detach().contiguous().numpy()


_NUMPY_DTYPES = {torch.float64: np.float64, torch.float32: np.float32}


def predict(xb: Tensor, Pb: Tensor, Qb: Tensor, dt: float) -> tuple[Tensor, Tensor, Tensor]:
    """Batch-last prediction ``(x- (13, B), P- (13, 13, B), Ghat (4, 7, B))`` from ``xb (13, B)``,
    ``Pb (13, 13, B)``, ``Qb (13, 13, B or 1)`` (any strides, copied where not contiguous; ``Qb``
    is read batch-first, so a ``Q`` stored ``(B, 13, 13)``, as noise parameters are, is not
    copied), CPU, one float dtype (:func:`supports`); ``dt`` in seconds. No autograd (the
    caller's :class:`~fkn_bench.filters.structured._PosePredict` is)."""
    batch, dtype = xb.shape[1], _NUMPY_DTYPES[xb.dtype]
    x_out, P_out, Ghat = np.empty((13, batch), dtype), np.empty((13, 13, batch), dtype), np.empty((4, 7, batch), dtype)
    source, coefficient = _g_sparsity(float(dt))
    _kernels()["predict_forward"](
        _array(xb), _array(Pb), _array(Qb.permute(2, 0, 1)), float(dt), source, coefficient,
        x_out, P_out, Ghat, np.empty((7, 13, batch), dtype), np.empty((7, 4, batch), dtype),
    )
    return torch.from_numpy(x_out), torch.from_numpy(P_out), torch.from_numpy(Ghat)


def predict_backward(
    xb: Tensor, Pb: Tensor, Ghat: Tensor, g_mean: Tensor, g_P: Tensor, dt: float, q_batch: int
) -> tuple[Tensor, Tensor, Tensor]:
    """``(dL/dx (13, B), dL/dP (13, 13, B), dL/dQ (13, 13, q_batch))`` of :func:`predict` given
    the output gradients ``g_mean (13, B)``, ``g_P (13, 13, B)``; ``q_batch`` is ``Q``'s batch
    axis (1: shared, its gradient summed over the batch). ``dL/dx`` is a ``(13, B)`` view of
    ``(B, 13)`` storage, laid out as the means are; a per-row ``dL/dQ`` a view of ``(B, 13, 13)``
    storage, as ``Q`` is."""
    batch, dtype = xb.shape[1], _NUMPY_DTYPES[xb.dtype]
    per_row = q_batch == batch and batch != 1
    dx, dP, dQ = np.empty((batch, 13), dtype), np.empty((13, 13, batch), dtype), np.empty((batch if per_row else 1, 13, 13), dtype)
    g_P = g_P.contiguous()
    source, coefficient = _g_sparsity(float(dt))
    _kernels()["predict_backward"](
        _array(xb), _array(Pb), _array(Ghat), _array(g_mean), g_P.numpy(), float(dt), source, coefficient,
        dx, dP, dQ, np.empty((7, 13, batch), dtype), np.empty((4, 7, batch), dtype),
    )
    if not per_row:
        summed = g_P.sum(-1, keepdim=True)
        return torch.from_numpy(dx).transpose(0, 1), torch.from_numpy(dP), (summed + summed.transpose(0, 1)) * 0.5
    return torch.from_numpy(dx).transpose(0, 1), torch.from_numpy(dP), torch.from_numpy(dQ).permute(1, 2, 0)
