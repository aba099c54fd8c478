"""Compiled CPU kernels (numba) of the pose-twist EKF step: prediction and measurement update,
forward and backward.

:mod:`fkn_bench.filters.structured` forms the step from the model's structure (``F = I + Delta``,
``H = [I7 0]``, see that module) as a few dozen torch operations on batch-last ``(13, 13, B)``
blocks; at B = 64 (a training batch) each costs more in dispatch than in arithmetic, and at
B = 1024 each makes its own pass over memory. These kernels do the same arithmetic (equal to
rounding: ``tests/filters/test_kernels.py``) in one call per step, with the batch innermost, so
that the compiler vectorises it; :func:`predict_steps` and its backward run a stretch of
predictions (steps without a measurement) through them on numpy views, with a few microseconds of
overhead per step. They run on CPU float64 tensors (the filters' default; any
strides: inputs that are not C-contiguous are copied); anything else (a GPU, float32) takes the
torch operations, which stay the reference implementation.

``fkn-bench bench run -k step_paths`` times the EKF's ``run()`` with and without them
(``fkn_bench/DESIGN.md``, "Performance notes").

Compilation (``numba.njit``, ``cache=True``) happens on first use, a few seconds per kernel, and
is cached on disk beside this file (or in numba's user cache directory where that is
read-only). :data:`ENABLED` switches the kernels off (the torch operations then run everywhere),
which is how the tests compare the two. :func:`warm_up` (``fkn-bench bench compile``) compiles
every kernel at once (tens of seconds in a fresh environment, under a second once cached). The test command runs it before pytest, so that
the two test workers do not both compile the kernels inside whichever tests first reach them.
"""

from __future__ import annotations

import functools
import math
import os
from typing import Any

import numpy as np
import torch
from torch import Tensor

__all__ = ["ENABLED", "supports", "predict", "predict_backward", "predict_steps", "predict_steps_backward", "update",
           "update_backward"]

ENABLED: bool = os.environ.get("FKN_BENCH_KERNELS", "1") != "0"
"""Whether :func:`supports` may say yes (environment ``FKN_BENCH_KERNELS=0`` turns the kernels
off at import; tests set the attribute)."""

_DTYPES = (torch.float64,)
"""The dtypes the kernels run on: float64, the filters' default. float32 batches take the torch
operations (each dtype would be one more compilation of every kernel on first use)."""


@functools.cache
def _numba() -> Any:
    """The numba module, or None when it cannot be imported (the torch operations then run)."""
    try:
        import numba
    except ImportError:  # pragma: no cover - numba is a dependency; a broken install falls back
        return None
    return numba


def supports(*tensors: Tensor) -> bool:
    """Whether the kernels can run on these tensors: CPU, float64 (:data:`_DTYPES`), kernels
    enabled and numba importable."""
    if not ENABLED:
        return False
    dtype = tensors[0].dtype
    for t in tensors:  # (a loop, not any() over a generator: this runs at every step)
        if not t.is_cpu or t.dtype is not dtype:
            return False
    return dtype in _DTYPES and _numba() is not None


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

def _predict_backward_kernel(x, P_q, P_w, Ghat, g_mean, g_P, dt, source, coefficient, dx, X, dQ, Xu, dG):  # type: ignore[no-untyped-def]
    """The backward pass of :class:`fkn_bench.filters.structured._PosePredict` (same
    operations per entry): ``x (13, B)``, the input covariance's rows ``q`` and ``w``, ``P_q (4,
    13, B)`` and ``P_w (3, 13, B)`` (all it reads of ``P``: the columns ``u`` of the product
    ``dG = 2 X[:, q]^T P[:, u]`` are these rows, ``P`` being exactly symmetric, as every covariance
    of the filters is), ``Ghat (4, 7, B)``, the output
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
    for i in range(4):  # dG = 2 X[:, q]^T P[:, u] + (g_q x_q^T on the columns q); P[:, u] = P[u, :]^T
        for k in range(7):
            P_u = P_q[k] if k < 4 else P_w[k - 4]  # (13, B): row u of P
            for b in range(B):
                dG[i, k, b] = X[0, i, b] * P_u[0, b]
            for a in range(1, 13):
                for b in range(B):
                    dG[i, k, b] += X[a, i, b] * P_u[a, b]
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


def _update_forward_kernel(x, P, nu, S, R, mean, P_out, Si, K, A, TK, N, Y, M, Pp, norm):  # type: ignore[no-untyped-def]
    """The measurement update of :func:`fkn_bench.filters.structured.pose_update` (the torch
    operations' factored Joseph form, vectorised over the batch): ``x (13, B)``,
    ``P (13, 13, B)``, the innovation ``nu (7, B)``, ``S = P[o, o] + R (7, 7, B)``,
    ``R (B or 1, 7, 7)`` -> ``mean (13, B)`` (the quaternion renormalised), ``P_out (13, 13, B)``
    (exactly symmetric), and for the backward pass ``Si = S^-1 (7, 7, B)``, ``K (13, 7, B)``;
    the rest is scratch. ``S`` is inverted by Gauss-Jordan elimination without pivoting
    (symmetric positive definite: Golub & Van Loan, Matrix Computations, 4th ed., sec. 4.2), as
    the torch operations' solve is."""
    B = x.shape[1]
    per_row_r = R.shape[0] != 1
    for i in range(7):  # [S | I] -> [I | S^-1]: Gauss-Jordan without pivoting (S SPD)
        for j in range(7):
            for b in range(B):
                A[i, j, b] = S[i, j, b]
            one = 1.0 if i == j else 0.0
            for b in range(B):
                A[i, 7 + j, b] = one
    for k in range(7):
        for c in range(k + 1, 14):
            for b in range(B):
                A[k, c, b] = A[k, c, b] / A[k, k, b]
        for r in range(7):
            if r != k:
                for c in range(k + 1, 14):
                    for b in range(B):
                        A[r, c, b] -= A[r, k, b] * A[k, c, b]
    for i in range(7):
        for j in range(7):
            for b in range(B):
                Si[i, j, b] = A[i, 7 + j, b]
    for a in range(13):  # K = P[:, o] S^-1; x+ = x + K nu
        for b in range(B):
            mean[a, b] = x[a, b]
        for j in range(7):
            for b in range(B):
                s = P[a, 0, b] * Si[0, j, b]
                s += P[a, 1, b] * Si[1, j, b]
                s += P[a, 2, b] * Si[2, j, b]
                s += P[a, 3, b] * Si[3, j, b]
                s += P[a, 4, b] * Si[4, j, b]
                s += P[a, 5, b] * Si[5, j, b]
                s += P[a, 6, b] * Si[6, j, b]
                K[a, j, b] = s
                mean[a, b] += s * nu[j, b]
    for b in range(B):
        norm[b] = math.sqrt(mean[0, b] * mean[0, b] + mean[1, b] * mean[1, b] + mean[2, b] * mean[2, b] + mean[3, b] * mean[3, b])
    for i in range(4):
        for b in range(B):
            mean[i, b] = mean[i, b] / norm[b]
    for i in range(4):  # N = (I - u u^T) / |q|
        for k in range(4):
            one = 1.0 if i == k else 0.0
            for b in range(B):
                N[i, k, b] = (one - mean[i, b] * mean[k, b]) / norm[b]
    for i in range(4):  # TK[q] = N K[q] (TK's other rows are K's)
        for j in range(7):
            for b in range(B):
                TK[i, j, b] = N[i, 0, b] * K[0, j, b] + N[i, 1, b] * K[1, j, b] + N[i, 2, b] * K[2, j, b] + N[i, 3, b] * K[3, j, b]
    for a in range(13):  # Y = T P - (T K) P[o, :]
        for c in range(13):
            if a < 4:
                for b in range(B):
                    z = TK[a, 0, b] * P[0, c, b]
                    for k in range(1, 7):
                        z += TK[a, k, b] * P[k, c, b]
                    tp = N[a, 0, b] * P[0, c, b] + N[a, 1, b] * P[1, c, b] + N[a, 2, b] * P[2, c, b] + N[a, 3, b] * P[3, c, b]
                    Y[a, c, b] = tp - z
            else:
                for b in range(B):
                    z = K[a, 0, b] * P[0, c, b]
                    for k in range(1, 7):
                        z += K[a, k, b] * P[k, c, b]
                    Y[a, c, b] = P[a, c, b] - z
    for a in range(13):  # M = (T K) R - Y[:, o]
        for j in range(7):
            if per_row_r:
                if a < 4:
                    for b in range(B):
                        s = TK[a, 0, b] * R[b, 0, j]
                        for k in range(1, 7):
                            s += TK[a, k, b] * R[b, k, j]
                        M[a, j, b] = s - Y[a, j, b]
                else:
                    for b in range(B):
                        s = K[a, 0, b] * R[b, 0, j]
                        for k in range(1, 7):
                            s += K[a, k, b] * R[b, k, j]
                        M[a, j, b] = s - Y[a, j, b]
            else:
                if a < 4:
                    for b in range(B):
                        s = TK[a, 0, b] * R[0, 0, j]
                        for k in range(1, 7):
                            s += TK[a, k, b] * R[0, k, j]
                        M[a, j, b] = s - Y[a, j, b]
                else:
                    for b in range(B):
                        s = K[a, 0, b] * R[0, 0, j]
                        for k in range(1, 7):
                            s += K[a, k, b] * R[0, k, j]
                        M[a, j, b] = s - Y[a, j, b]
    for a in range(13):  # P+ = M (T K)^T + Y T^T
        for c in range(13):
            if c < 4:
                for b in range(B):
                    s = M[a, 0, b] * TK[c, 0, b]
                    for j in range(1, 7):
                        s += M[a, j, b] * TK[c, j, b]
                    s += Y[a, 0, b] * N[c, 0, b] + Y[a, 1, b] * N[c, 1, b] + Y[a, 2, b] * N[c, 2, b] + Y[a, 3, b] * N[c, 3, b]
                    Pp[a, c, b] = s
            else:
                for b in range(B):
                    s = M[a, 0, b] * K[c, 0, b]
                    for j in range(1, 7):
                        s += M[a, j, b] * K[c, j, b]
                    Pp[a, c, b] = s + Y[a, c, b]
    for a in range(13):
        for c in range(13):
            for b in range(B):
                P_out[a, c, b] = (Pp[a, c, b] + Pp[c, a, b]) * 0.5


def _update_backward_kernel(x, P, nu, R, Si, K, N, TKq, Y, M, norm, g_mean, g_P, dx, dP, dnu, dS, dR, G, dM, dTK, dY, dN, dK, q, dq, dSi, W):  # type: ignore[no-untyped-def]
    """The backward pass of :func:`_update_forward_kernel`, vectorised over the batch: from the inputs and what
    the forward saved (``Si``, ``K``, ``N``, ``TK``'s quaternion rows, ``Y``, ``M``, ``|q|``;
    batch-last), then (reverse mode, with
    ``G = sym(g_P)``): ``P+ = M (TK)^T + Y T^T``, ``M = (TK) R - Y[:, o]``, ``Y = T P - (TK) P[o, :]``,
    ``TK = T K``, ``T``'s block ``N = I/n - q q^T/n^3`` and the mean's ``u = q/n``, ``x+ = x + K nu``,
    ``K = P[:, o] S^-1`` (``d S^-1 = -S^-1 dS S^-1``). Outputs ``dx (13, B)``, ``dP (13, 13, B)``,
    ``dnu (7, B)``, ``dS (7, 7, B)`` and ``dR`` (summed over the batch when ``R`` is shared)."""
    B = x.shape[1]
    per_row_r = R.shape[0] != 1
    for i in range(4):  # q = x + K nu (the quaternion before renormalisation)
        for b in range(B):
            q[i, b] = x[i, b]
        for j in range(7):
            for b in range(B):
                q[i, b] += K[i, j, b] * nu[j, b]
    for a in range(13):  # G = sym(g_P)
        for c in range(13):
            for b in range(B):
                G[a, c, b] = (g_P[a, c, b] + g_P[c, a, b]) * 0.5
    # (The heavy products below accumulate term by term into one batch-long row, in the order
    # of the sums they replace, so the results are the same to the bit: a sum over a small axis
    # inside the batch loop would read up to 40 rows 8 kB apart at B = 1024, which share L1
    # cache sets.)
    for a in range(13):  # dM = G TK, dTK = G M (P+ = M TK^T + Y T^T, G symmetric)
        for j in range(7):
            for b in range(B):
                dM[a, j, b] = G[a, 0, b] * TKq[0, j, b]
                dTK[a, j, b] = G[a, 0, b] * M[0, j, b]
            for c in range(1, 13):
                if c < 4:
                    for b in range(B):
                        dM[a, j, b] += G[a, c, b] * TKq[c, j, b]
                else:
                    for b in range(B):
                        dM[a, j, b] += G[a, c, b] * K[c, j, b]
                for b in range(B):
                    dTK[a, j, b] += G[a, c, b] * M[c, j, b]
    for a in range(13):  # dY = G T (columns q: G[:, q] N)
        for c in range(13):
            if c < 4:
                for b in range(B):
                    dY[a, c, b] = G[a, 0, b] * N[0, c, b] + G[a, 1, b] * N[1, c, b] + G[a, 2, b] * N[2, c, b] + G[a, 3, b] * N[3, c, b]
            else:
                for b in range(B):
                    dY[a, c, b] = G[a, c, b]
    for e in range(4):  # dN = G[:, q]^T Y[:, q]
        for k in range(4):
            for b in range(B):
                s = 0.0
                for a in range(13):
                    s += G[a, e, b] * Y[a, k, b]
                dN[e, k, b] = s
    for a in range(13):  # M = TK R - Y[:, o]: dTK += dM R^T, dR += TK^T dM, dY[:, o] -= dM
        for k in range(7):
            if per_row_r:
                for b in range(B):
                    s = 0.0
                    for j in range(7):
                        s += dM[a, j, b] * R[b, k, j]
                    dTK[a, k, b] += s
            else:
                for b in range(B):
                    s = 0.0
                    for j in range(7):
                        s += dM[a, j, b] * R[0, k, j]
                    dTK[a, k, b] += s
    row = np.empty(B)  # one (k, j) entry of TK^T dM along the batch
    for k in range(7):
        for j in range(7):
            for b in range(B):
                row[b] = TKq[0, k, b] * dM[0, j, b]
            for a in range(1, 13):
                if a < 4:
                    for b in range(B):
                        row[b] += TKq[a, k, b] * dM[a, j, b]
                else:
                    for b in range(B):
                        row[b] += K[a, k, b] * dM[a, j, b]
            if per_row_r:
                for b in range(B):
                    dR[b, k, j] = row[b]
            else:
                total = 0.0
                for b in range(B):
                    total += row[b]
                dR[0, k, j] = total
    for a in range(13):
        for j in range(7):
            for b in range(B):
                dY[a, j, b] -= dM[a, j, b]
    for k in range(13):  # Y = T P - TK P[o, :]: dP = T^T dY - (k < 7) TK^T dY
        for c in range(13):
            if k < 4:
                for b in range(B):
                    dP[k, c, b] = N[0, k, b] * dY[0, c, b] + N[1, k, b] * dY[1, c, b] + N[2, k, b] * dY[2, c, b] + N[3, k, b] * dY[3, c, b]
            else:
                for b in range(B):
                    dP[k, c, b] = dY[k, c, b]
            if k < 7:
                for a in range(13):
                    if a < 4:
                        for b in range(B):
                            dP[k, c, b] -= TKq[a, k, b] * dY[a, c, b]
                    else:
                        for b in range(B):
                            dP[k, c, b] -= K[a, k, b] * dY[a, c, b]
    for i in range(4):  # dN += dY[q] P[q]^T
        for k in range(4):
            for b in range(B):
                s = 0.0
                for c in range(13):
                    s += dY[i, c, b] * P[k, c, b]
                dN[i, k, b] += s
    for a in range(13):  # dTK -= dY P[o]^T
        for k in range(7):
            for b in range(B):
                row[b] = dY[a, 0, b] * P[k, 0, b]
            for c in range(1, 13):
                for b in range(B):
                    row[b] += dY[a, c, b] * P[k, c, b]
            for b in range(B):
                dTK[a, k, b] -= row[b]
    for a in range(13):  # TK = [N K[q]; K[4:]]: dK, and dN += dTK[q] K[q]^T
        for j in range(7):
            if a < 4:
                for b in range(B):
                    dK[a, j, b] = N[0, a, b] * dTK[0, j, b] + N[1, a, b] * dTK[1, j, b] + N[2, a, b] * dTK[2, j, b] + N[3, a, b] * dTK[3, j, b]
            else:
                for b in range(B):
                    dK[a, j, b] = dTK[a, j, b]
    for i in range(4):
        for k in range(4):
            for b in range(B):
                s = 0.0
                for j in range(7):
                    s += dTK[i, j, b] * K[k, j, b]
                dN[i, k, b] += s
    for b in range(B):  # N = I/n - q q^T/n^3, the mean's u = q/n: dq
        n = norm[b]
        n3 = n * n * n
        trace = dN[0, 0, b] + dN[1, 1, b] + dN[2, 2, b] + dN[3, 3, b]
        qdq = 0.0
        for i in range(4):
            for k in range(4):
                qdq += q[i, b] * dN[i, k, b] * q[k, b]
        for m in range(4):
            s = -trace * q[m, b] / n3
            t = 0.0
            for k in range(4):
                t += (dN[m, k, b] + dN[k, m, b]) * q[k, b]
            s -= t / n3
            s += 3.0 * qdq * q[m, b] / (n3 * n * n)
            for k in range(4):
                s += N[m, k, b] * g_mean[k, b]
            dq[m, b] = s
    for a in range(13):  # x+ = x + K nu
        for b in range(B):
            dx[a, b] = dq[a, b] if a < 4 else g_mean[a, b]
        for j in range(7):
            for b in range(B):
                dK[a, j, b] += dx[a, b] * nu[j, b]
    for j in range(7):
        for b in range(B):
            s = 0.0
            for a in range(13):
                s += K[a, j, b] * dx[a, b]
            dnu[j, b] = s
    for a in range(13):  # K = P[:, o] S^-1: dP[:, o] += dK S^-T
        for k in range(7):
            for b in range(B):
                s = 0.0
                for j in range(7):
                    s += dK[a, j, b] * Si[k, j, b]
                dP[a, k, b] += s
    for k in range(7):  # dSi = P[:, o]^T dK; dS = -S^-T dSi S^-T
        for j in range(7):
            for b in range(B):
                s = 0.0
                for a in range(13):
                    s += P[a, k, b] * dK[a, j, b]
                dSi[k, j, b] = s
    for k in range(7):
        for j in range(7):
            for b in range(B):
                s = 0.0
                for l in range(7):
                    s += dSi[k, l, b] * Si[j, l, b]
                W[k, j, b] = s
    for i in range(7):
        for j in range(7):
            for b in range(B):
                s = 0.0
                for k in range(7):
                    s += Si[k, i, b] * W[k, j, b]
                dS[i, j, b] = -s


_KERNELS = (_predict_forward_kernel, _predict_backward_kernel, _update_forward_kernel, _update_backward_kernel)


@functools.cache
def _kernels() -> dict[str, Any]:
    """The compiled kernels (compiled once per process on first call; numba's on-disk cache
    makes that a load after the first process)."""
    numba = _numba()
    names = ("predict_forward", "predict_backward", "update_forward", "update_backward")
    try:
        jit = numba.njit(cache=True, nogil=True, boundscheck=False)
        return {name: jit(kernel) for name, kernel in zip(names, _KERNELS)}
    except RuntimeError:  # pragma: no cover - no writable cache directory: compile in every process
        jit = numba.njit(cache=False, nogil=True, boundscheck=False)
        return {name: jit(kernel) for name, kernel in zip(names, _KERNELS)}


def _array(t: Tensor) -> np.ndarray:
    """A C-contiguous numpy view of ``t`` (copied first when it is not contiguous)."""
    return t.detach().contiguous().numpy()


_NUMPY_DTYPES = {torch.float64: np.float64}


def predict(xb: Tensor, Pb: Tensor, Qb: Tensor, dt: float, g_sparsity: tuple[np.ndarray, np.ndarray]) -> tuple[Tensor, Tensor, Tensor]:
    """Batch-last prediction ``(x- (13, B), P- (13, 13, B), Ghat (4, 7, B))`` from ``xb (13, B)``,
    ``Pb (13, 13, B)``, ``Qb (13, 13, B or 1)`` (any strides, copied where not contiguous; ``Qb``
    is read batch-first, so a ``Q`` stored ``(B, 13, 13)``, as noise parameters are, is not
    copied), CPU float64 (:func:`supports`); ``dt`` in seconds; ``g_sparsity`` the
    ``(source, coefficient)`` of ``Ghat``'s entries
    (:func:`fkn_bench.filters.structured.g_sparsity`). No autograd (the caller's
    :class:`~fkn_bench.filters.structured._PosePredict` is)."""
    batch, dtype = xb.shape[1], _NUMPY_DTYPES[xb.dtype]
    x_out, P_out, Ghat = np.empty((13, batch), dtype), np.empty((13, 13, batch), dtype), np.empty((4, 7, batch), dtype)
    source, coefficient = g_sparsity
    _kernels()["predict_forward"](
        _array(xb), _array(Pb), _array(Qb.permute(2, 0, 1)), float(dt), source, coefficient,
        x_out, P_out, Ghat, np.empty((7, 13, batch), dtype), np.empty((7, 4, batch), dtype),
    )
    return torch.from_numpy(x_out), torch.from_numpy(P_out), torch.from_numpy(Ghat)


def predict_backward(
    xb: Tensor, Pb: Tensor, Ghat: Tensor, g_mean: Tensor, g_P: Tensor, dt: float, q_batch: int,
    g_sparsity: tuple[np.ndarray, np.ndarray],
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
    source, coefficient = g_sparsity
    P = _array(Pb)
    _kernels()["predict_backward"](
        _array(xb), P[0:4], P[7:10], _array(Ghat), _array(g_mean), g_P.numpy(), float(dt), source, coefficient,
        dx, dP, dQ, np.empty((7, 13, batch), dtype), np.empty((4, 7, batch), dtype),
    )
    if not per_row:
        summed = g_P.sum(-1, keepdim=True)
        return torch.from_numpy(dx).transpose(0, 1), torch.from_numpy(dP), (summed + summed.transpose(0, 1)) * 0.5
    return torch.from_numpy(dx).transpose(0, 1), torch.from_numpy(dP), torch.from_numpy(dQ).permute(1, 2, 0)


def predict_steps(
    xb: Tensor, Pb: Tensor, Q: Tensor, dt: float, count: int, g_sparsity: tuple[np.ndarray, np.ndarray], *,
    keep: str = "every",
) -> tuple[Tensor, Tensor, Tensor, Tensor | None]:
    """``count`` batch-last predictions in a row (a stretch of steps without a measurement):
    ``(xs (count, 13, B), Ps, Ghats, P_rows)``, the means after every step and the covariances
    ``keep`` asks for, from ``xb (13, B)``, ``Pb (13, 13, B)`` and ``Q (Bq, Tq, 13, 13)``, ``Bq``
    1 or B, ``Tq`` 1 (the same at every step) or ``count``. Each step is :func:`predict`'s
    compiled kernel, bit for bit, called on numpy views of preallocated series: a few
    microseconds of overhead per step, where a step through torch and autograd costs about a
    hundred. (The loop is Python: a compiled loop calling the step kernel tripled the compile
    time, which every fresh install and CI run pays.) No autograd (the caller's
    :class:`~fkn_bench.filters.structured._PosePredictSteps` is).

    ``keep``:

    * ``"every"``: every step's covariance, ``Ps (count, 13, 13, B)``, and ``Ghats (count, 4, 7,
      B)``; ``P_rows`` None.
    * ``"last"`` (a run without autograd that stores no covariances): ``Ps`` holds two, written in
      turn, the last at ``(count - 1) % 2``, ``Ghats`` one, ``P_rows`` None. A fresh series of
      every step's covariance cost more in page zeroing than the predictions themselves at
      B = 1024.
    * ``"rows"`` (autograd, no covariances stored): ``Ps`` and ``Ghats (count, 4, 7, B)`` as for
      ``"every"`` but two slots of ``Ps``, and ``P_rows (count - 1, 7, 13, B)``, the rows ``q``
      and ``w`` of the covariance after every step but the last: all that
      :func:`predict_steps_backward` reads of them (:func:`_predict_backward_kernel`), 7/13 of
      the memory a full series writes.
    """
    if keep not in ("every", "last", "rows"):
        raise ValueError(f"keep must be 'every', 'last' or 'rows' (got {keep!r})")
    batch, dtype = xb.shape[1], _NUMPY_DTYPES[xb.dtype]
    e = np.empty
    every = keep == "every"
    slots = count if every else min(count, 2)
    xs, Ps = e((count, 13, batch), dtype), e((slots, 13, 13, batch), dtype)
    Ghats = e((1 if keep == "last" else count, 4, 7, batch), dtype)
    P_rows = e((count - 1, 7, 13, batch), dtype) if keep == "rows" else None
    D, corner = e((7, 13, batch), dtype), e((7, 4, batch), dtype)
    source, coefficient = g_sparsity
    step = _kernels()["predict_forward"]
    x, P, noise = _array(xb), _array(Pb), _array(Q.transpose(0, 1))  # noise[j]: step j's (Bq, 13, 13)
    per_step = noise.shape[0] != 1
    for j in range(count):
        slot = j if every else j % 2
        step(x, P, noise[j if per_step else 0], float(dt), source, coefficient, xs[j], Ps[slot], Ghats[0 if keep == "last" else j],
             D, corner)
        x, P = xs[j], Ps[slot]
        if P_rows is not None and j < count - 1:
            P_rows[j, 0:4], P_rows[j, 4:7] = P[0:4], P[7:10]
    return torch.from_numpy(xs), torch.from_numpy(Ps), torch.from_numpy(Ghats), None if P_rows is None else torch.from_numpy(P_rows)


def predict_steps_backward(
    xb: Tensor, Pb: Tensor, xs: Tensor, Ps: Tensor, Ghats: Tensor, g_xs: Tensor, g_Ps: Tensor, dt: float,
    q_shape: tuple[int, int], g_sparsity: tuple[np.ndarray, np.ndarray],
) -> tuple[Tensor, Tensor, Tensor]:
    """``(dL/dx (13, B), dL/dP (13, 13, B), dL/dQ (Bq, Tq, 13, 13))`` of :func:`predict_steps`
    from its inputs ``xb``, ``Pb``, its means ``xs``, the covariances of every step but the last,
    whole ``Ps (>= count - 1, 13, 13, B)`` or their rows ``q`` and ``w`` (``P_rows``, ``(count -
    1, 7, 13, B)``), and ``Ghats``, given the gradients of every step's mean ``g_xs (count, 13,
    B)`` and of every step's
    covariance, or of the last only, ``g_Ps (count or 1, 13, 13, B)``; ``q_shape`` is ``(Bq,
    Tq)``, ``Q``'s leading axes. Each step's backward is :func:`predict_backward`'s kernel, in
    reverse order; ``dL/dQ`` sums ``sym(dL/dP-)`` over the steps that share a ``Q`` (and over the
    batch when ``Bq`` is 1). ``dL/dx`` is a ``(13, B)`` view of ``(B, 13)`` storage, laid out as
    the means are."""
    count, batch, dtype = xs.shape[0], xb.shape[1], _NUMPY_DTYPES[xb.dtype]
    e = np.empty
    rows, per_step = q_shape
    per_row = rows != 1
    dQ = np.zeros((per_step, rows, 13, 13), dtype)  # time-major: dQ[t] is one step's
    dQ_step = e((batch, 13, 13), dtype) if per_row else e((1, 13, 13), dtype)  # (the kernel fills a per-row one)
    dx, g_mean = e((batch, 13), dtype), e((13, batch), dtype)
    g_P, X = e((13, 13, batch), dtype), e((13, 13, batch), dtype)  # (C-contiguous, as the kernel was compiled for)
    Xu, dG = e((7, 13, batch), dtype), e((4, 7, batch), dtype)
    source, coefficient = g_sparsity
    step = _kernels()["predict_backward"]
    x_all, P_all, G_all = _array(xs), _array(Ps), _array(Ghats)
    w = slice(7, 10) if P_all.shape[1] == 13 else slice(4, 7)  # (the rows w of a whole P, or of P_rows)
    g_means, g_covariances = _array(g_xs), _array(g_Ps)
    every = g_covariances.shape[0] == count and count != 1
    g_mean[:], g_P[:] = g_means[count - 1], g_covariances[count - 1 if every else 0]
    for j in range(count - 1, -1, -1):
        if j == 0:
            x, P = _array(xb), _array(Pb)
            P_q, P_w = P[0:4], P[7:10]
        else:
            x, P_q, P_w = x_all[j - 1], P_all[j - 1, 0:4], P_all[j - 1, w]
        step(x, P_q, P_w, G_all[j], g_mean, g_P, float(dt), source, coefficient, dx, X, dQ_step, Xu, dG)
        t = j if per_step != 1 else 0
        if per_row:
            dQ[t] += dQ_step
        else:  # sym(dL/dP-) summed over the batch
            summed = g_P.sum(-1)
            dQ[t, 0] += (summed + summed.T) * 0.5
        if j:  # step j - 1's output gradients: its own plus step j's input gradients
            np.add(g_means[j - 1], dx.T, out=g_mean)
            g_P, X = X, g_P  # (the kernel reads g_P and writes X: they must not be one buffer)
            if every:
                g_P += g_covariances[j - 1]
    return torch.from_numpy(dx).transpose(0, 1), torch.from_numpy(X), torch.from_numpy(dQ).transpose(0, 1)


def update(xb: Tensor, Pb: Tensor, nub: Tensor, S: Tensor, R: Tensor) -> tuple[Tensor, ...]:
    """The pose-twist measurement update, batch-last: ``xb (13, B)``, ``Pb (13, 13, B)``, the
    innovation ``nub (7, B)``, ``S = P[o, o] + R`` ``(7, 7, B)``, ``R (B or 1, 7, 7)``
    (batch-first) -> ``(x+ (13, B), P+ (13, 13, B), *saved)``, ``saved`` what
    :func:`update_backward` takes (``S^-1``, ``K``, ``N``, ``TK[q]``, ``Y``, ``M``, ``|q|``). No
    autograd (the caller's :class:`~fkn_bench.filters.structured._PoseUpdate` is)."""
    batch, dtype = xb.shape[1], _NUMPY_DTYPES[xb.dtype]
    e = np.empty
    mean, P_out = e((13, batch), dtype), e((13, 13, batch), dtype)
    saved = (e((7, 7, batch), dtype), e((13, 7, batch), dtype), e((4, 4, batch), dtype), e((4, 7, batch), dtype),
             e((13, 13, batch), dtype), e((13, 7, batch), dtype), e(batch, dtype))
    S_inv, K, N, TK, Y, M, norm = saved
    _kernels()["update_forward"](
        _array(xb), _array(Pb), _array(nub), _array(S), _array(R), mean, P_out, S_inv, K,
        e((7, 14, batch), dtype), TK, N, Y, M, e((13, 13, batch), dtype), norm,
    )
    return (torch.from_numpy(mean), torch.from_numpy(P_out), *(torch.from_numpy(a) for a in saved))


def update_backward(
    xb: Tensor, Pb: Tensor, nub: Tensor, R: Tensor, saved: tuple[Tensor, ...], g_mean: Tensor, g_P: Tensor
) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
    """``(dL/dx (13, B), dL/dP (13, 13, B), dL/dnu (7, B), dL/dS (7, 7, B), dL/dR (B or 1, 7, 7))``
    of :func:`update` given what it ``saved`` and the output gradients ``g_mean (13, B)``,
    ``g_P (13, 13, B)``."""
    batch, dtype = xb.shape[1], _NUMPY_DTYPES[xb.dtype]
    e = np.empty
    dx, dP, dnu = e((13, batch), dtype), e((13, 13, batch), dtype), e((7, batch), dtype)
    dS, dR = e((7, 7, batch), dtype), e(tuple(R.shape), dtype)
    _kernels()["update_backward"](
        _array(xb), _array(Pb), _array(nub), _array(R), *(_array(t) for t in saved), _array(g_mean), _array(g_P),
        dx, dP, dnu, dS, dR,
        e((13, 13, batch), dtype), e((13, 7, batch), dtype), e((13, 7, batch), dtype), e((13, 13, batch), dtype),
        e((4, 4, batch), dtype), e((13, 7, batch), dtype), e((4, batch), dtype), e((4, batch), dtype),
        e((7, 7, batch), dtype), e((7, 7, batch), dtype),
    )
    return tuple(torch.from_numpy(a) for a in (dx, dP, dnu, dS, dR))  # type: ignore[return-value]


def warm_up() -> list[str]:
    """Compile (or load from numba's disk cache) every kernel by running the EKF once, forward and
    backward, on a small batch that reaches each of them: a measurement update, stretches of
    steps without a measurement (:func:`predict_steps`) and single predictions; and the rigid-body
    model's kernels (:mod:`fkn_bench.models.rigid_body_kernels`): the free-tumble truth's
    integrator (one test split of tumble-fast) and the model's numpy transition with its Jacobian
    (one state, estimated and known inertia); returns the names of the EKF kernels compiled. Raises ``RuntimeError`` when the
    kernels cannot run here (numba missing, or switched off by ``FKN_BENCH_KERNELS=0``)."""
    from fkn_bench.envs import generate_episodes
    from fkn_bench.filters import make_filter
    from fkn_bench.models.noise import NoiseParameters
    from fkn_bench.models.rigid_body import RigidBodyModel
    from fkn_bench.scenarios.scenario import ASTROBEE_INERTIA

    probe = torch.zeros(1, dtype=torch.float64)
    if not supports(probe):
        raise RuntimeError("the compiled kernels are off here (numba missing, or FKN_BENCH_KERNELS=0)")
    episodes = generate_episodes("ds1", [0, 1], split="test")
    z = torch.from_numpy(np.array(episodes.measurements[:, :40]))
    mask = torch.from_numpy(np.array(episodes.valid[:, :40]))
    mask[1, 5:25] = False  # a longer stretch without a measurement in one row
    log_q = torch.full((13,), math.log(1e-3), dtype=torch.float64, requires_grad=True)
    noise = NoiseParameters.from_std(torch.exp(log_q), [0.1] * 7, [0.1] * 13)
    result = make_filter("ekf").run(noise, z, mask, dt=float(episodes.scenario.dt))
    torch.autograd.grad(result.means.square().mean(), log_q)
    generate_episodes("tumble-fast", [0], split="test")  # the free-tumble truth's integrator
    RigidBodyModel(estimate_ratios=True).transition(np.eye(1, 15), 0.1)  # the rigid-body model's transition,
    RigidBodyModel(inertia=ASTROBEE_INERTIA).transition(np.eye(1, 13), 0.1)  # known inertia: another signature
    return [name for name, kernel in _kernels().items() if kernel.signatures]

