"""The EKF step of :class:`~fkn_bench.models.pose_twist.PoseTwistModel` on torch batches, written for
the model's structure (the large-batch hot path of :class:`~fkn_bench.filters.ekf.ExtendedKalmanFilter`,
from :data:`~fkn_bench.filters.ekf.STRUCTURED_MIN_BATCH` rows).

The generic step (:func:`fkn_bench.filters.ekf.ekf_predict`, :func:`~fkn_bench.filters.ekf.joseph_update`)
forms ``F P F^T`` and the Joseph products as dense ``(B, 13, 13)`` batched matrix products; a
batched product of 13 x 13 matrices costs about as much per matrix in call overhead as in
arithmetic. These functions work *batch-last* instead: a covariance is read as a ``(13, 13, B)``
view (``P.permute(1, 2, 0)``; free when it is stored that way, as every covariance they return
is) and a small product ``X (a, k, B) @ Y (k, c, B)`` is ``k`` fused multiply-adds of ``(a, c, B)``
blocks (:func:`_product`), elementwise work vectorised over the batch, with its own backward
(:class:`_BatchLastProduct`). Inputs and outputs keep the public shapes: means ``(B, 13)``,
covariances ``(B, 13, 13)`` (views of batch-last storage), so :meth:`KalmanFilter.run` and
everything downstream see no difference but for the strides.

Structure used (state ``[q(4), r(3), w(3), v(3)]``, FlexKalmanNet eqs. 6-11):

* The transition Jacobian is ``F = I + Delta``: ``Delta`` nonzero on the quaternion rows, on the
  columns ``u = [q, w]`` (``Ghat = [dt/2 Omega(w) | dt/2 Theta(q)]``, 4 x 7), and on the position
  rows (``dt`` on the velocity columns). With ``D = (Delta P)[q r, :]`` and
  ``N = D + (Delta P Delta^T)[q r, q r] / 2``, ``F P F^T = P + N + N^T`` (:func:`_predict_forward`):
  4 x 7 x 13 plus 7 x 7 x 4 multiply-adds instead of two dense 13^3 products, and exactly
  symmetric by construction when ``P`` is. The predict has a hand-written backward
  (:class:`_PosePredict`: one autograd node per step).
* ``H = [I7 0]``: ``S = P[o, o] + R`` with ``o = 0:7``, ``K = P[:, o] S^-1`` (13 x 7 x 7). The
  Joseph update (Bucy & Joseph 1968; Simon, Optimal State Estimation, 2006, eq. 5.19) followed by
  the normalisation's projection ``T`` (identity but for ``N = (I - u u^T)/|q|`` on the ``q``
  block), ``P+ = (T A) P (T A)^T + (T K) R (T K)^T`` with ``A = I - K H``, is formed as
  ``Y = (T A) P = T P - (T K) P[o, :]`` and ``P+ = Y T^T + ((T K) R - Y[:, o]) (T K)^T``
  (``Y (T A)^T`` with ``(T A)^T = T^T - H^T (T K)^T``): the factored Joseph form with the
  products on their nonzero blocks, two 13 x 7 x 13 products; then symmetrised.

Covariances returned are exactly symmetric (the update's symmetrised as the generic step's; the
predict's by construction, given an exactly symmetric ``P``: every covariance the filters
produce and :class:`~fkn_bench.filters.parameters.NoiseParameters`' ``P0`` are; ``Q`` is
symmetrised). The quaternion sign alignment and the measured slice go through the model's own
``align`` and ``measure`` hooks on the public layout, so the sign rule is the model's, unchanged.
Outputs equal the generic step's to rounding (``tests/filters/test_structured.py``).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from torch import Tensor

from fkn_bench.filters import kernels
from fkn_bench.filters.base import FilterState
from fkn_bench.geometry import quaternion as qx
from fkn_bench.linalg import constant

__all__ = ["pose_predict", "pose_predict_steps", "pose_update", "batch_last", "batch_first"]

_U = (0, 1, 2, 3, 7, 8, 9)
"""The state components ``[q, w]`` on which the quaternion rows of ``F`` depend."""


def batch_last(P: Tensor) -> Tensor:
    """``(B, k, k)`` -> ``(k, k, B)`` view (``(k, k)`` -> ``(k, k, 1)``)."""
    return P.unsqueeze(-1) if P.dim() == 2 else P.permute(1, 2, 0)


def batch_first(P: Tensor) -> Tensor:
    """``(k, k, B)`` -> ``(B, k, k)`` view."""
    return P.permute(2, 0, 1)


def _product(X: Tensor, Y: Tensor) -> Tensor:
    """``X @ Y`` of batch-last matrices ``X (a, k, B)``, ``Y (k, c, B)`` (a batch axis of 1
    broadcasts): ``sum_k X[:, k] Y[k]`` (:func:`_sum_of_outer`); differentiable
    (:class:`_BatchLastProduct`)."""
    if torch.is_grad_enabled() and (X.requires_grad or Y.requires_grad):
        return _BatchLastProduct.apply(X, Y)
    return _sum_of_outer(_columns(X), _rows(Y))


def _columns(X: Tensor) -> tuple[Tensor, ...]:
    """The columns of batch-last ``X (a, k, B)`` as ``k`` views ``(a, 1, B)``."""
    return X.unsqueeze(2).unbind(1)


def _rows(Y: Tensor) -> tuple[Tensor, ...]:
    """The rows of batch-last ``Y (k, c, B)`` as ``k`` views ``(1, c, B)``."""
    return Y.unsqueeze(0).unbind(1)


def _sum_of_outer(columns: Sequence[Tensor], rows: Sequence[Tensor], out: Tensor | None = None) -> Tensor:
    """``sum_k columns[k] rows[k]`` with ``columns[k] (a, 1, B)`` and ``rows[k] (1, c, B)``
    (:func:`_columns`, :func:`_rows`) -> ``(a, c, B)`` (into ``out`` when given): the product of
    the matrices with these columns and rows, as ``k`` fused multiply-adds into one ``(a, c, B)``
    buffer, which stays in cache (a broadcast product and a sum would write a ``k`` times larger
    intermediate). Not differentiable: :func:`_product` is."""
    if out is None:  # contiguous, whatever the strides of the operands
        column, row = columns[0], rows[0]
        out = torch.empty(column.shape[0], row.shape[1], max(column.shape[2], row.shape[2]), dtype=column.dtype, device=column.device)
    torch.mul(columns[0], rows[0], out=out)
    for column, row in zip(columns[1:], rows[1:]):
        out.addcmul_(column, row)
    return out


class _BatchLastProduct(torch.autograd.Function):
    """``X (a, k, B) @ Y (k, c, B)`` batch-last (either batch axis may be 1), with the backward
    pass ``dX = dO Y^T``, ``dY = X^T dO`` as the same fused multiply-adds (summed over a broadcast
    batch axis): no ``(a, k, c, B)`` intermediate forward or backward."""

    @staticmethod
    def forward(ctx: Any, X: Tensor, Y: Tensor) -> Tensor:  # type: ignore[override]
        ctx.save_for_backward(X, Y)
        return _sum_of_outer(_columns(X), _rows(Y))

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx: Any, g: Tensor) -> tuple[Tensor | None, Tensor | None]:  # type: ignore[override]
        X, Y = ctx.saved_tensors
        dX = dY = None
        if ctx.needs_input_grad[0]:
            dX = _sum_of_outer(_columns(g), _rows(Y.transpose(0, 1)))  # sum_c dO[:, c] Y[:, c]^T
            if X.shape[-1] == 1 and dX.shape[-1] != 1:
                dX = dX.sum(-1, keepdim=True)
        if ctx.needs_input_grad[1]:
            dY = _sum_of_outer(_columns(X.transpose(0, 1)), _rows(g))  # sum_i X[i]^T dO[i]
            if Y.shape[-1] == 1 and dY.shape[-1] != 1:
                dY = dY.sum(-1, keepdim=True)
        return dX, dY


def _g_basis(dt: float) -> np.ndarray:
    """``C (28, 13)`` with ``C x = Ghat`` flattened row-major (4 x 7) for states ``x (13, B)``:
    ``Ghat = [dt/2 Omega(w) | dt/2 Theta(q)]``, the quaternion rows of ``F - I`` on the columns
    ``u = [q, w]``; linear in ``x`` (FlexKalmanNet eqs. 8-11)."""
    basis = np.zeros((4, 7, 13))  # [row i, column k of Ghat, state component j]
    theta, omega = qx.theta_matrix(np.eye(4)), qx.omega_matrix(np.eye(3))  # (4, 4, 3), (3, 4, 4)
    for j in range(4):  # d(Theta(q))/dq_j
        basis[:, 4:7, j] = theta[j]
    for j in range(3):  # d(Omega(w))/dw_j
        basis[:, 0:4, 7 + j] = omega[j]
    return (0.5 * dt) * basis.reshape(28, 13)


@functools.cache
def g_sparsity(dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``(source, coefficient)`` per entry ``r`` of ``Ghat`` (4 x 7, row-major): ``Ghat[r] =
    coefficient[r] * x[source[r]]`` (each entry of ``[dt/2 Omega(w) | dt/2 Theta(q)]`` is one
    signed state component or zero: :func:`fkn_bench.filters.structured._g_basis`)."""
    basis = _g_basis(dt)
    source, coefficient = np.zeros(28, dtype=np.int64), np.zeros(28)
    for r in range(28):
        (nonzero,) = np.nonzero(basis[r])
        if nonzero.size > 1:  # pragma: no cover - a property of the model, checked here once
            raise AssertionError("each entry of the pose-twist model's Ghat is one state component")
        if nonzero.size:
            source[r], coefficient[r] = nonzero[0], basis[r, nonzero[0]]
    return source, coefficient


def _g_constants(like: Tensor, dt: float) -> tuple[Tensor, Tensor]:
    """``(C (28, 13), I_u (4, 7, 1))``: ``Ghat = (C x).view(4, 7, B)`` (:func:`_g_basis`) and
    ``G = F[q, u] = Ghat + I_u``."""
    C = constant(like, ("pose-G", dt), lambda: _g_basis(dt))
    eye = constant(like, "pose-G-eye", lambda: np.concatenate((np.eye(4), np.zeros((4, 3))), axis=1)[:, :, None])
    return C, eye


def pose_predict(state: FilterState, process_noise: Tensor, dt: float) -> FilterState:
    """EKF prediction of :class:`PoseTwistModel` (module docstring): ``x- = f(x+)``,
    ``P- = F P+ F^T + Q``, symmetrised. ``state``: means ``(B, 13)``, covariances ``(B, 13, 13)``
    (any strides; exactly symmetric, as every covariance of the filters is: the gradient with
    respect to the mean relies on it); ``Q`` ``(13, 13)`` or ``(B or 1, 13, 13)``; ``dt`` in
    seconds. Returns views of batch-last storage with the public shapes. Differentiable through a
    hand-written backward (:class:`_PosePredict`), which keeps the autograd graph at one node
    per step."""
    inputs = (state.mean.transpose(0, 1), batch_last(state.covariance), batch_last(process_noise))
    if torch.is_grad_enabled() and (inputs[0].requires_grad or inputs[1].requires_grad or inputs[2].requires_grad):
        mean, P_next = _PosePredict.apply(*inputs, float(dt))
    else:  # nothing to differentiate: no autograd.Function call (its overhead is a tenth of a step)
        mean, P_next, _ = _forward(*inputs, float(dt))
    return FilterState(mean.transpose(0, 1), batch_first(P_next))


def pose_predict_steps(
    state: FilterState, process_noise: Tensor, dt: float, count: int, *, per_step: bool = False,
    store_covariances: bool = True,
) -> tuple[Tensor, Tensor | None, FilterState]:
    """``count`` predictions in a row (:func:`pose_predict` each, bit for bit) by the compiled
    kernels (:func:`fkn_bench.filters.kernels.predict_steps`; CPU float64 only:
    :func:`fkn_bench.filters.kernels.supports`) and, under autograd, one node
    (:class:`_PosePredictSteps`): a stretch of steps without a measurement (nine in ten on ds1)
    costs about one step's overhead. ``process_noise``: ``Q`` ``(13, 13)`` or ``(B or 1, 13,
    13)`` at every step or, with ``per_step``, ``(B or 1, count, 13, 13)``.

    Returns, as :meth:`~fkn_bench.filters.base.KalmanFilter.predict_steps`, the means
    ``(count - 1, B, 13)`` and covariances ``(count - 1, B, 13, 13)`` (None unless
    ``store_covariances``) of the states before the last, and the last state: views of
    batch-last storage."""
    Q = process_noise if per_step else (process_noise if process_noise.dim() == 3 else process_noise[None]).unsqueeze(1)
    inputs = (state.mean.transpose(0, 1), batch_last(state.covariance), Q)
    if torch.is_grad_enabled() and any(t.requires_grad for t in inputs):
        means, mean, covariance, covariances = _PosePredictSteps.apply(*inputs, float(dt), count, store_covariances)
    else:
        xs, Ps, _, _ = kernels.predict_steps(*inputs, float(dt), count, g_sparsity(float(dt)),
                                             keep="every" if store_covariances else "last")
        last = count - 1 if store_covariances else (count - 1) % 2
        means, mean, covariance, covariances = xs[:-1], xs[-1], Ps[last], Ps[:-1]
    final = FilterState(mean.transpose(0, 1), batch_first(covariance))
    return means.permute(0, 2, 1), covariances.permute(0, 3, 1, 2) if store_covariances else None, final


class _PosePredictSteps(torch.autograd.Function):
    """``(x (13, B), P (13, 13, B), Q (Bq, Tq, 13, 13), dt, count, every_P) -> (xs (count - 1,
    13, B), x- (13, B), P- (13, 13, B), Ps)``, the means before the last, the last state, and the
    covariances before the last ``(count - 1, 13, 13, B)`` when ``every_P``, else none ``(0, 13,
    13, B)`` (a run that stores no covariances gets no gradient buffer for them), by the compiled
    kernels (:func:`fkn_bench.filters.kernels.predict_steps`,
    :func:`~fkn_bench.filters.kernels.predict_steps_backward`). The last state is an output of
    its own, not a selection of a series, whose backward would fill a zeroed gradient of the
    whole series. Without ``every_P`` the backward pass keeps only the rows of each covariance it
    reads (``keep="rows"``: 7 of 13 rows)."""

    @staticmethod
    def forward(ctx: torch.autograd.function.FunctionCtx, xb: Tensor, Pb: Tensor, Q: Tensor, dt: float, count: int,  # type: ignore[override]
                every_P: bool) -> tuple[Tensor, Tensor, Tensor, Tensor]:
        xs, Ps, Ghats, P_rows = kernels.predict_steps(xb, Pb, Q, dt, count, g_sparsity(dt), keep="every" if every_P else "rows")
        ctx.save_for_backward(xb, Pb, xs, Ps if P_rows is None else P_rows, Ghats)
        ctx.dt, ctx.q_shape, ctx.every_P = dt, tuple(Q.shape[:2]), every_P
        last = count - 1 if every_P else (count - 1) % 2
        return xs[:-1], xs[-1], Ps[last], Ps[:-1] if every_P else Ps[:0]

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx: Any, g_means: Tensor, g_mean: Tensor, g_P: Tensor, g_Ps: Tensor) -> tuple[Tensor | None, ...]:  # type: ignore[override]
        xb, Pb, xs, Ps, Ghats = ctx.saved_tensors
        g_xs = torch.cat((g_means, g_mean[None]))
        g_Ps = torch.cat((g_Ps, g_P[None])) if ctx.every_P else g_P[None]
        gradients = kernels.predict_steps_backward(xb, Pb, xs, Ps, Ghats, g_xs, g_Ps, ctx.dt, ctx.q_shape, g_sparsity(ctx.dt))
        return (*(g if needed else None for g, needed in zip(gradients, ctx.needs_input_grad)), None, None, None)


def _forward(xb: Tensor, Pb: Tensor, Qb: Tensor, dt: float) -> tuple[Tensor, Tensor, Tensor]:
    """:func:`_predict_forward` by the compiled kernel where it runs (:func:`kernels.supports`:
    CPU float64), else by the torch operations."""
    if kernels.supports(xb, Pb, Qb):
        return kernels.predict(xb, Pb, Qb, dt, g_sparsity(dt))
    return _predict_forward(xb, Pb, Qb, dt)


def _predict_forward(xb: Tensor, Pb: Tensor, Qb: Tensor, dt: float) -> tuple[Tensor, Tensor, Tensor]:
    """Batch-last prediction ``(x- (13, B), P- (13, 13, B), Ghat (4, 7, B))``, ``Ghat`` for the
    backward pass.

    ``F = I + Delta`` with ``Delta`` nonzero on the ``q`` rows (``Ghat = [dt/2 Omega(w) | dt/2
    Theta(q)]`` on the columns ``u``) and the ``r`` rows (``dt`` on the ``v`` columns). With
    ``D = (Delta P)[q r, :]`` (7 x 13) and ``N = D + (Delta P Delta^T)[q r, q r] / 2`` (its 7 x 7
    block only), ``F P F^T = P + N + N^T`` with ``N`` placed on the rows ``q r`` and ``N^T`` on the
    columns ``q r``. Written as ``(P + Q) + N`` on one side of the diagonal, ``(P + Q) + N^T`` on
    the other and ``(P + Q) + (N + N^T)`` on the 7 x 7 block, the result is exactly symmetric when
    ``P`` and ``Q`` are (``Q`` is symmetrised here; ``P`` is every covariance the filter
    produces), with no symmetrising pass over the whole matrix.
    """
    batch = xb.shape[1]
    C, _ = _g_constants(xb, dt)
    Ghat = (C @ xb).view(4, 7, batch)  # [dt/2 Omega(w) | dt/2 Theta(q)]
    q_next = xb[0:4] + (Ghat[:, 0:4] * xb[0:4]).sum(1)  # q + dt/2 Omega(w) q
    mean = torch.cat((q_next, torch.add(xb[4:7], xb[10:13], alpha=dt), xb[7:13]))  # (13, B)
    P_rows = _rows(Pb)
    D = torch.empty(7, 13, batch, dtype=Pb.dtype, device=Pb.device)
    _sum_of_outer(_columns(Ghat), [P_rows[i] for i in _U], out=D[0:4])  # Ghat P[u]
    torch.mul(Pb[10:13], dt, out=D[4:7])  # dt P[v]
    D_columns = _columns(D)
    corner = _sum_of_outer([D_columns[i] for i in _U], _rows(Ghat.transpose(0, 1)))  # (Delta P Delta^T)[q r, q]: D[:, u] Ghat^T
    N = D  # D + (Delta P Delta^T)[q r, q r] / 2, in place (the q and r columns; D[:, u] and D[:, v] were read)
    N[:, 0:4].add_(corner, alpha=0.5)
    N[:, 4:7].add_(D[:, 10:13], alpha=0.5 * dt)
    P_next = torch.empty(13, 13, batch, dtype=Pb.dtype, device=Pb.device)  # batch-last, whatever P's layout
    torch.add(Pb, _symmetrized(Qb), out=P_next)
    P_next[0:7, 0:7] += N[:, 0:7] + N[:, 0:7].transpose(0, 1)
    P_next[0:7, 7:13] += N[:, 7:13]
    P_next[7:13, 0:7] += N[:, 7:13].transpose(0, 1)
    return mean, P_next, Ghat


class _PosePredict(torch.autograd.Function):
    """``(x (13, B), P (13, 13, B), Q (13, 13, B or 1), dt) -> (x-, P-)`` batch-last, with the
    backward pass written out (``Gbar = sym(dL/dP-)``):

    * ``dL/dQ = Gbar`` (summed over a broadcast batch axis), ``dL/dP = F^T Gbar F`` (the same
      structured products as the forward pass, with ``F^T``);
    * ``dL/dG = 2 Gbar[q, :] (F P)[:, u]`` (``P`` symmetric) plus ``dL/dq- q^T`` from the mean
      ``q- = G[:, q] q``; ``dL/dx`` collects ``C^T dL/dG`` (``G`` is affine in ``x_u``) and the
      mean's direct terms.
    """

    @staticmethod
    def forward(ctx: torch.autograd.function.FunctionCtx, xb: Tensor, Pb: Tensor, Qb: Tensor, dt: float) -> tuple[Tensor, Tensor]:  # type: ignore[override]
        mean, P_next, Ghat = _forward(xb, Pb, Qb, dt)
        ctx.save_for_backward(xb, Pb, Ghat)
        ctx.dt = dt
        ctx.q_shape = Qb.shape
        return mean, P_next

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx: Any, g_mean: Tensor, g_P: Tensor) -> tuple[Tensor | None, Tensor | None, Tensor | None, None]:  # type: ignore[override]
        xb, Pb, Ghat = ctx.saved_tensors
        dt = ctx.dt
        batch = xb.shape[1]
        if kernels.supports(xb, Pb, Ghat, g_mean, g_P):  # the same arithmetic, compiled
            dx, dP, dQ = kernels.predict_backward(xb, Pb, Ghat, g_mean, g_P, dt, ctx.q_shape[-1], g_sparsity(dt))
            return (dx if ctx.needs_input_grad[0] else None, dP if ctx.needs_input_grad[1] else None,
                    dQ if ctx.needs_input_grad[2] else None, None)
        C, eye = _g_constants(xb, dt)
        G = Ghat + eye  # F[q, u]
        Gbar = _symmetrized(g_P)
        dQ = None
        if ctx.needs_input_grad[2]:
            dQ = Gbar if ctx.q_shape[-1] == batch and batch != 1 else Gbar.sum(-1, keepdim=True)
        dx = dP = None
        if not (ctx.needs_input_grad[0] or ctx.needs_input_grad[1]):
            return dx, dP, dQ, None
        # X = F^T Gbar, in place in Gbar's buffer (a fresh tensor; copied when it is dQ): rows
        # q = G[:, q]^T Gbar[q], w += G[:, w]^T Gbar[q], v += dt Gbar[r] (r unchanged)
        X = Gbar.clone() if dQ is Gbar else Gbar
        Xu = _product(G.transpose(0, 1), X[0:4])  # (7, 13, B)
        X[0:4] = Xu[0:4]
        X[7:10] += Xu[4:7]
        X[10:13].add_(X[4:7], alpha=dt)
        if ctx.needs_input_grad[0]:
            # dL/dG = 2 (Gbar F P)[q, u] = 2 X[:, q]^T P[:, u]  (Gbar, P symmetric: Gbar F = X^T)
            g_q = g_mean[0:4]
            dG = _product(X[:, 0:4].transpose(0, 1), torch.cat((Pb[:, 0:4], Pb[:, 7:10]), dim=1))  # (4, 7, B)
            dG *= 2.0
            dG[:, 0:4] += g_q.unsqueeze(1) * xb[0:4].unsqueeze(0)  # from the mean q- = G[:, q] q
            dq = (G[:, 0:4] * g_q.unsqueeze(1)).sum(0)
            g_r = g_mean[4:7]
            direct = torch.cat((dq, g_r, g_mean[7:10], torch.add(g_mean[10:13], g_r, alpha=dt)))  # f's linear part
            dx = torch.addmm(direct, C.transpose(0, 1), dG.view(28, batch))  # + C^T dL/dGhat: Ghat = C x
            # laid out as the (B, 13) means are, so that autograd sums it with their other
            # gradients (the stacked outputs') without a strided add
            dx = dx.transpose(0, 1).contiguous().transpose(0, 1)
        if ctx.needs_input_grad[1]:
            # dL/dP = X F: columns q = X[:, q] G[:, q], w += X[:, q] G[:, w], v += dt X[:, r]
            Yu = _product(X[:, 0:4], G)  # (13, 7, B)
            X[:, 0:4] = Yu[:, 0:4]
            X[:, 7:10] += Yu[:, 4:7]
            X[:, 10:13].add_(X[:, 4:7], alpha=dt)
            dP = X
        return dx, dP, dQ, None


def _innovation(xb: Tensor, Pb: Tensor, zb: Tensor, R: Tensor) -> tuple[Tensor, Tensor]:
    """``(nu (7, B), S (7, 7, B))`` batch-last for the aligned measurement ``zb (7, B)`` and
    ``R (B or 1, 7, 7)`` batch-first: ``nu = z - x[o]``, ``S = P[o, o] + R`` (``H = [I7 0]``; a
    block of ``P`` plus ``R``: exactly symmetric, as they are)."""
    return zb - xb[0:7], Pb[0:7, 0:7] + R.permute(1, 2, 0)


class _PoseUpdate(torch.autograd.Function):
    """``(x (13, B), P (13, 13, B), z (7, B), R (B or 1, 7, 7)) -> (x+, P+, nu, S)`` batch-last,
    with ``z`` the aligned measurement, ``nu = z - x[o]`` and ``S = P[o, o] + R`` (``H = [I7 0]``),
    by the compiled kernels (:func:`fkn_bench.filters.kernels.update` and its backward,
    :func:`~fkn_bench.filters.kernels.update_backward`): one autograd node per update, where the
    torch operations make about forty. ``nu`` and ``S`` are formed here rather than by the
    caller, whose slices of ``x`` and ``P`` would each add a backward node filling a zeroed
    gradient of the whole ``x`` or ``P``; their gradients go to ``x[o]``, ``P[o, o]``, ``z`` and
    ``R`` in the backward pass."""

    @staticmethod
    def forward(ctx: torch.autograd.function.FunctionCtx, xb: Tensor, Pb: Tensor, zb: Tensor, R: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor]:  # type: ignore[override]
        nub, S = _innovation(xb, Pb, zb, R)
        mean, P_post, *saved = kernels.update(xb, Pb, nub, S, R)
        ctx.save_for_backward(xb, Pb, nub, R, *saved)
        ctx.set_materialize_grads(False)
        return mean, P_post, nub, S

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx: Any, g_mean: Tensor | None, g_P: Tensor | None, g_nu: Tensor | None, g_S: Tensor | None) -> tuple[Tensor | None, ...]:  # type: ignore[override]
        xb, Pb, nub, R, *saved = ctx.saved_tensors
        g_mean = torch.zeros_like(xb) if g_mean is None else g_mean
        g_P = torch.zeros_like(Pb) if g_P is None else g_P
        dx, dP, dnu, dS, dR = kernels.update_backward(xb, Pb, nub, R, tuple(saved), g_mean, g_P)
        if g_nu is not None:
            dnu += g_nu
        if g_S is not None:
            dS += g_S
        dx[0:7] -= dnu  # nu = z - x[o]
        dP[0:7, 0:7] += dS  # S = P[o, o] + R
        dR += dS.permute(2, 0, 1) if R.shape[0] != 1 else dS.sum(-1).unsqueeze(0)
        needed = ctx.needs_input_grad
        return (dx if needed[0] else None, dP if needed[1] else None, dnu if needed[2] else None, dR if needed[3] else None)


def _symmetrized(Pb: Tensor) -> Tensor:
    """``(P + P^T) / 2`` of a batch-last ``(k, k, B)`` batch (exactly symmetric; the transposed
    operand is read along the contiguous batch axis, so this costs one vectorised add)."""
    out = Pb + Pb.transpose(0, 1)
    out *= 0.5
    return out


def _solve_spd(S: Tensor, rhs: Tensor) -> Tensor:
    """``S^-1 rhs`` for batch-last symmetric positive definite ``S (m, m, B)`` and ``rhs (m, c, B)``
    by Gauss-Jordan elimination without pivoting (stable for symmetric positive definite
    matrices: Golub & Van Loan, Matrix Computations, 4th ed., sec. 4.2), vectorised over the
    batch; not differentiable (the update under autograd uses ``inv_ex``)."""
    m = S.shape[0]
    M = torch.cat((S, rhs.expand(m, rhs.shape[1], S.shape[2])), dim=1)  # [S | rhs], reduced to [I | S^-1 rhs]
    for k in range(m):
        row = M[k, k + 1 :] / M[k, k]
        column = M[:, k].clone()
        column[k] = 0.0
        M[:, k + 1 :].addcmul_(column.unsqueeze(1), row.unsqueeze(0), value=-1.0)
        M[k, k + 1 :] = row
    return M[:, m:]


def pose_update(model: object, state: FilterState, z: Tensor, measurement_noise: Tensor) -> tuple[FilterState, Tensor, Tensor]:
    """EKF measurement update of :class:`PoseTwistModel` for every row (module docstring):
    ``z (B, 7)`` sanitised measurements, ``R`` ``(7, 7)`` or ``(B or 1, 7, 7)``. The measured
    quaternion's sign is aligned by ``model.align`` (as the generic update does); the posterior
    quaternion is renormalised and the covariance projected with ``N = (I - u u^T) / |q|``.
    Returns the posterior (means ``(B, 13)``, covariances ``(B, 13, 13)``, symmetrised), the
    innovation ``nu (B, 7)`` and its covariance ``S (B, 7, 7)`` (exactly symmetric). On CPU float64
    tensors the update runs as compiled kernels (:func:`fkn_bench.filters.kernels.update`,
    :class:`_PoseUpdate`); elsewhere as torch operations: the gain from :func:`_solve_spd`
    without autograd, from ``inv_ex`` with it (equal to rounding); without autograd the products
    are formed in place in their buffers."""
    x, P = state.mean, state.covariance
    z = model.align(z, x)  # type: ignore[attr-defined]
    Pb = batch_last(P)
    if kernels.supports(x, P, measurement_noise, z):  # the same update, compiled
        R_rows = measurement_noise if measurement_noise.dim() == 3 else measurement_noise.unsqueeze(0)
        inputs = (x.transpose(0, 1), Pb, z.transpose(0, 1), R_rows)
        if torch.is_grad_enabled() and any(t.requires_grad for t in inputs):
            mean, P_post, nub, S = _PoseUpdate.apply(*inputs)
        else:
            nub, S = _innovation(*inputs)
            mean, P_post, *_ = kernels.update(inputs[0], Pb, nub, S, R_rows)
        return FilterState(mean.transpose(0, 1), batch_first(P_post)), nub.transpose(0, 1), batch_first(S)
    nu = z - model.measure(x)  # type: ignore[attr-defined]
    Rb = batch_last(measurement_noise)
    S = Pb[0:7, 0:7] + Rb  # a block of P plus R: exactly symmetric, as they are
    if torch.is_grad_enabled() and (P.requires_grad or measurement_noise.requires_grad):
        S_inv = torch.linalg.inv_ex(batch_first(S))[0].permute(1, 2, 0).contiguous()  # batch-last, contiguous
        K = _product(Pb[:, 0:7], S_inv)  # (13, 7, B): P H^T S^-1
    else:
        K = _solve_spd(S, Pb[0:7]).transpose(0, 1)  # K^T = S^-1 H P (P symmetric)
    xb = x.transpose(0, 1) + (K * nu.transpose(0, 1).unsqueeze(0)).sum(1)  # (13, B)
    q = xb[0:4]
    norm = torch.sqrt((q * q).sum(0, keepdim=True))  # (1, B)
    unit = q / norm
    N = (constant(x, "eye4-bl", lambda: np.eye(4)[:, :, None]) - unit.unsqueeze(1) * unit.unsqueeze(0)) / norm  # (4, 4, B)
    mean = torch.cat((unit, xb[4:13]))
    TK = torch.cat((_product(N, K[0:4]), K[4:13]))  # (13, 7, B)
    # Y = T A P = T P - (T K) P[o, :];  P+ = Y T^T + ((T K) R - Y[:, o]) (T K)^T
    Z = _product(TK, Pb[0:7])
    if not Z.requires_grad:  # in place in the products' buffers
        Y = Z.neg_()
        Y[0:4] += _product(N, Pb[0:4])
        Y[4:13] += Pb[4:13]
        P_post = _product(_product(TK, Rb) - Y[:, 0:7], TK.transpose(0, 1))
        P_post[:, 0:4] += _product(Y[:, 0:4], N.transpose(0, 1))
        P_post[:, 4:13] += Y[:, 4:13]
    else:  # blocks joined by cat, whose backward slices (an in-place slice's backward fills a zeroed copy)
        Y = torch.cat((_product(N, Pb[0:4]) - Z[0:4], Pb[4:13] - Z[4:13]))
        P_post = _product(_product(TK, Rb) - Y[:, 0:7], TK.transpose(0, 1))
        P_post = P_post + torch.cat((_product(Y[:, 0:4], N.transpose(0, 1)), Y[:, 4:13]), dim=1)
    return FilterState(mean.transpose(0, 1), batch_first(_symmetrized(P_post))), nu, batch_first(S)
