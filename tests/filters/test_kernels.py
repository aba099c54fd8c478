"""The compiled CPU kernels of the pose-twist EKF step (:mod:`fkn_bench.filters.kernels`) against
the torch operations they replace (:mod:`fkn_bench.filters.structured`): the prediction (one step,
and several in one call against the steps one by one) and the measurement update, forward values
and every gradient to rounding, with ``Q`` and ``R`` shared and per row, from inputs of any
strides; and where they do not run (float32 among them)."""

from __future__ import annotations

import pytest
import torch

from fkn_bench.filters import FilterState, kernels
from fkn_bench.models import PoseTwistModel
from fkn_bench.filters.structured import _PosePredict, _PosePredictSteps, _predict_forward, g_sparsity, pose_update


def batch_last_inputs(batch: int, q_batch: int, seed: int) -> tuple[torch.Tensor, ...]:
    """``x (13, B)``, symmetric ``P (13, 13, B)``, symmetric ``Q (13, 13, q_batch)``."""
    g = torch.Generator().manual_seed(seed)
    x = torch.randn(13, batch, generator=g, dtype=torch.float64)
    x[:4] /= x[:4].norm(dim=0, keepdim=True)
    A = 0.3 * torch.randn(batch, 13, 13, generator=g, dtype=torch.float64)
    P = (A @ A.transpose(1, 2) + 0.05 * torch.eye(13, dtype=torch.float64)).permute(1, 2, 0)
    L = 0.1 * torch.randn(q_batch, 13, 13, generator=g, dtype=torch.float64)
    Q = (L @ L.transpose(1, 2)).permute(1, 2, 0)
    return x, 0.5 * (P + P.transpose(0, 1)), 0.5 * (Q + Q.transpose(0, 1))


def predict_with_gradients(enabled: bool, x: torch.Tensor, P: torch.Tensor, Q: torch.Tensor, seed: int) -> list[torch.Tensor]:
    """``x-``, ``P-`` and the gradients of a random linear function of them with respect to
    ``x``, ``P`` and ``Q``, by the kernels (``enabled``) or the torch operations."""
    previous, kernels.ENABLED = kernels.ENABLED, enabled
    try:
        inputs = [t.clone().requires_grad_(True) for t in (x, P, Q)]
        mean, P_next = _PosePredict.apply(*inputs, 0.1)
        g = torch.Generator().manual_seed(seed)
        g_mean, g_P = (torch.randn(t.shape, generator=g, dtype=torch.float64) for t in (mean, P_next))
        gradients = torch.autograd.grad((mean, P_next), inputs, (g_mean, g_P))
    finally:
        kernels.ENABLED = previous
    return [mean.detach(), P_next.detach(), *gradients]


@pytest.mark.parametrize("batch,q_batch", [(1, 1), (5, 1), (5, 5), (70, 70)])
def test_kernels_equal_the_torch_operations(batch: int, q_batch: int) -> None:
    x, P, Q = batch_last_inputs(batch, q_batch, seed=batch + q_batch)
    assert kernels.supports(x, P, Q)
    compiled, reference = (predict_with_gradients(enabled, x, P, Q, seed=3) for enabled in (True, False))
    for name, a, b in zip(("x-", "P-", "dx", "dP", "dQ"), compiled, reference):
        assert a.shape == b.shape, name
        torch.testing.assert_close(a, b, rtol=1e-13, atol=1e-14, msg=name)
    assert torch.equal(compiled[1], compiled[1].transpose(0, 1))  # P- exactly symmetric, as the torch operations'


def test_kernels_read_inputs_of_any_strides() -> None:
    """Batch-first storage seen batch-last (the first prediction after a batch-first ``P0``), a
    strided mean, an expanded ``Q``: the kernels copy what is not contiguous."""
    x, P, Q = batch_last_inputs(6, 1, seed=11)
    x_strided = x.T.contiguous().T
    P_batch_first = P.permute(2, 0, 1).contiguous().permute(1, 2, 0)
    Q_expanded = Q.expand(13, 13, 6)
    compiled = kernels.predict(x_strided, P_batch_first, Q_expanded, 0.1, g_sparsity(0.1))
    reference = _predict_forward(x, P, Q_expanded.contiguous(), 0.1)
    for a, b in zip(compiled, reference):
        torch.testing.assert_close(a, b, rtol=1e-13, atol=1e-14)


def test_where_the_kernels_do_not_run(monkeypatch: pytest.MonkeyPatch) -> None:
    x, P, Q = batch_last_inputs(3, 1, seed=7)
    assert kernels.supports(x, P, Q)
    assert not kernels.supports(x.float(), P.float(), Q.float())  # float32: the torch operations
    assert not kernels.supports(x.float(), P, Q)  # mixed dtypes
    assert not kernels.supports(x.to("meta"), P, Q)  # not on the CPU
    monkeypatch.setattr(kernels, "ENABLED", False)
    assert not kernels.supports(x, P, Q)


def update_with_gradients(enabled: bool, batch: int, per_row: bool, seed: int) -> list[torch.Tensor]:
    """:func:`pose_update`'s outputs and the gradients of a random function of them with respect to
    ``x``, ``P`` and ``R``, by the kernels (``enabled``) or the torch operations. Every other
    measured quaternion has the other sign (aligned first, as the model aligns it)."""
    g = torch.Generator().manual_seed(seed)
    x, P, _ = batch_last_inputs(batch, 1, seed=seed)
    x, P = x.T.contiguous(), P.permute(2, 0, 1).contiguous()
    L = 0.1 * torch.randn(batch if per_row else 1, 7, 7, generator=g, dtype=torch.float64)
    R = L @ L.transpose(1, 2) + 0.01 * torch.eye(7, dtype=torch.float64)
    R = 0.5 * (R + R.transpose(1, 2))
    R = R if per_row else R[0]
    z = x[:, :7] + 0.05 * torch.randn(batch, 7, generator=g, dtype=torch.float64)
    z[::2, :4] *= -1
    weights = [torch.randn(shape, generator=g, dtype=torch.float64) for shape in ((batch, 13), (batch, 13, 13), (batch, 7), (batch, 7, 7))]
    previous, kernels.ENABLED = kernels.ENABLED, enabled
    try:
        inputs = [t.clone().requires_grad_(True) for t in (x, P, R)]
        state, nu, S = pose_update(PoseTwistModel(), FilterState(inputs[0], inputs[1]), z, inputs[2])
        outputs = (state.mean, state.covariance, nu, S)
        loss = sum((out * w).sum() for out, w in zip(outputs, weights))
        gradients = torch.autograd.grad(loss, inputs)
    finally:
        kernels.ENABLED = previous
    return [out.detach() for out in outputs] + list(gradients)


@pytest.mark.parametrize("batch,per_row", [(1, False), (5, False), (5, True), (70, True)])
def test_update_kernels_equal_the_torch_operations(batch: int, per_row: bool) -> None:
    compiled, reference = (update_with_gradients(enabled, batch, per_row, seed=batch) for enabled in (True, False))
    for name, a, b in zip(("x+", "P+", "nu", "S", "dx", "dP", "dR"), compiled, reference):
        assert a.shape == b.shape, name
        torch.testing.assert_close(a, b, rtol=1e-11, atol=1e-13, msg=name)
    assert torch.equal(compiled[1], compiled[1].transpose(1, 2))  # P+ exactly symmetric


@pytest.mark.parametrize("every_P", [False, True])
@pytest.mark.parametrize("batch,q_rows,per_step", [(1, 1, False), (5, 1, False), (5, 5, False), (5, 1, True), (5, 5, True)])
def test_predict_steps_equal_the_steps_one_by_one(batch: int, q_rows: int, per_step: bool, every_P: bool) -> None:
    """Several predictions in one call (:class:`_PosePredictSteps`): each step's state bit for bit
    the one-step kernel's, and the gradients with respect to ``x``, ``P`` and ``Q`` (shared, per
    row, per step) those of the steps chained by autograd, to rounding."""
    count = 4
    x, P, _ = batch_last_inputs(batch, 1, seed=batch + q_rows)
    g = torch.Generator().manual_seed(5)
    L = 0.1 * torch.randn(q_rows, count if per_step else 1, 13, 13, generator=g, dtype=torch.float64)
    Q = L @ L.transpose(-1, -2)
    inputs = [t.clone().requires_grad_(True) for t in (x, P, Q)]
    means, mean, covariance, covariances = _PosePredictSteps.apply(*inputs, 0.1, count, every_P)
    assert covariances.shape[0] == (count - 1 if every_P else 0)

    chained = [t.clone().requires_grad_(True) for t in (x, P, Q)]
    states = []
    state = (chained[0], chained[1])
    for j in range(count):
        state = _PosePredict.apply(*state, chained[2][:, j if per_step else 0].permute(1, 2, 0), 0.1)
        states.append(state)
    assert torch.equal(mean, states[-1][0]) and torch.equal(covariance, states[-1][1])
    assert torch.equal(means, torch.stack([s[0] for s in states[:-1]]))
    if every_P:
        assert torch.equal(covariances, torch.stack([s[1] for s in states[:-1]]))

    weights = [torch.randn(t.shape, generator=g, dtype=torch.float64) for t in (means, mean, covariance, covariances)]
    outputs = (means, mean, covariance, covariances)
    reference = (torch.stack([s[0] for s in states[:-1]]), states[-1][0], states[-1][1],
                 torch.stack([s[1] for s in states[:-1]])[: covariances.shape[0]])
    gradients = torch.autograd.grad(sum((o * w).sum() for o, w in zip(outputs, weights)), inputs)
    expected = torch.autograd.grad(sum((o * w).sum() for o, w in zip(reference, weights)), chained)
    for name, a, b in zip(("dx", "dP", "dQ"), gradients, expected):
        assert a.shape == b.shape, name
        torch.testing.assert_close(a, b, rtol=1e-12, atol=1e-14, msg=name)
