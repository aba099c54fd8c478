"""The pose-twist EKF's structured batch-last step (:mod:`fkn_bench.filters.structured`) against
the generic dense step (:func:`~fkn_bench.filters.ekf.ekf_predict`,
:func:`~fkn_bench.filters.ekf.linear_measurement_update`): values to rounding, gradients against
the dense step's autograd, the hand-written backward passes by finite differences, and a whole
``run()`` (the structured step forced at a small batch) against the generic one. Every test runs
twice: with the step's compiled CPU kernels (:mod:`fkn_bench.filters.kernels`) and with the torch
operations that run where they do not (a GPU, float32)."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from fkn_bench.filters import FilterState, make_filter
from fkn_bench.models import NoiseParameters, PoseTwistModel
from fkn_bench.filters import ekf, kernels
from fkn_bench.filters.ekf import ekf_predict, linear_measurement_update
from fkn_bench.filters.structured import _BatchLastProduct, _PosePredict, pose_predict, pose_update

MODEL = PoseTwistModel()


@pytest.fixture(autouse=True, params=["kernels", "torch-ops"])
def prediction_path(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    monkeypatch.setattr(kernels, "ENABLED", request.param == "kernels")
    return str(request.param)


def random_state(batch: int, seed: int) -> FilterState:
    """Unit quaternions, and exactly symmetric positive definite covariances, as the filter keeps."""
    g = torch.Generator().manual_seed(seed)
    x = torch.randn(batch, 13, generator=g, dtype=torch.float64)
    x[:, :4] /= x[:, :4].norm(dim=1, keepdim=True)
    A = 0.3 * torch.randn(batch, 13, 13, generator=g, dtype=torch.float64)
    P = A @ A.transpose(1, 2) + 0.05 * torch.eye(13, dtype=torch.float64)
    return FilterState(x, 0.5 * (P + P.transpose(1, 2)))


def noise(batch: int | None, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``Q (13, 13)``, ``R (7, 7)``, or per row ``(B, k, k)``: symmetric positive definite."""
    g = torch.Generator().manual_seed(seed)
    lead = () if batch is None else (batch,)
    out = []
    for k in (13, 7):
        L = 0.1 * torch.randn(*lead, k, k, generator=g, dtype=torch.float64)
        M = L @ L.transpose(-1, -2) + 0.01 * torch.eye(k, dtype=torch.float64)
        out.append(0.5 * (M + M.transpose(-1, -2)))
    return out[0], out[1]


@pytest.mark.parametrize("per_row", [False, True])
def test_structured_step_equals_the_dense_step(per_row: bool) -> None:
    state = random_state(5, seed=1)
    Q, R = noise(5 if per_row else None, seed=2)
    dense, fast = ekf_predict(MODEL, state, Q, 0.1), pose_predict(state, Q, 0.1)
    torch.testing.assert_close(fast.mean, dense.mean, rtol=1e-13, atol=1e-15)
    torch.testing.assert_close(fast.covariance, dense.covariance, rtol=1e-13, atol=1e-15)
    assert torch.equal(fast.covariance, fast.covariance.transpose(1, 2))  # exactly symmetric
    z = state.mean[:, :7] + 0.05 * torch.randn(5, 7, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    z[::2, :4] *= -1  # measured quaternions of the other sign: aligned as the dense step aligns them
    z[:, :4] /= z[:, :4].norm(dim=1, keepdim=True)
    (d_state, d_nu, d_S), (f_state, f_nu, f_S) = (step(MODEL, fast, z, R) for step in (linear_measurement_update, pose_update))
    for a, b in ((f_state.mean, d_state.mean), (f_state.covariance, d_state.covariance), (f_nu, d_nu), (f_S, d_S)):
        torch.testing.assert_close(a, b, rtol=1e-12, atol=1e-14)
    assert torch.equal(f_state.covariance, f_state.covariance.transpose(1, 2))


def test_structured_gradients_equal_the_dense_steps_autograd() -> None:
    g = torch.Generator().manual_seed(4)
    W = torch.randn(3, 13, 13, generator=g, dtype=torch.float64)
    w = torch.randn(3, 13, generator=g, dtype=torch.float64)
    base = random_state(3, seed=5)
    Q, R = noise(None, seed=6)
    z = base.mean[:, :7].clone()

    def gradients(predict, update) -> list[torch.Tensor]:
        x, P, Qg, Rg = (t.clone().requires_grad_(True) for t in (base.mean, base.covariance, Q, R))
        prior = predict(FilterState(x, P), Qg)
        posterior, nu, S = update(prior, z, Rg)
        loss = (posterior.mean * w).sum() + (posterior.covariance * W).sum() + nu.square().sum() + (S * W[:, :7, :7]).sum()
        return list(torch.autograd.grad(loss, (x, P, Qg, Rg)))

    dense = gradients(lambda s, Q_: ekf_predict(MODEL, s, Q_, 0.1), lambda s, z_, R_: linear_measurement_update(MODEL, s, z_, R_))
    fast = gradients(lambda s, Q_: pose_predict(s, Q_, 0.1), lambda s, z_, R_: pose_update(MODEL, s, z_, R_))
    for a, b in zip(fast, dense):
        torch.testing.assert_close(a, b, rtol=1e-10, atol=1e-12)


def test_hand_written_backward_passes_match_finite_differences() -> None:
    g = torch.Generator().manual_seed(7)
    X, Y, Y1 = (torch.randn(*shape, generator=g, dtype=torch.float64, requires_grad=True) for shape in ((3, 2, 2), (2, 4, 2), (2, 4, 1)))
    assert torch.autograd.gradcheck(_BatchLastProduct.apply, (X, Y))
    assert torch.autograd.gradcheck(_BatchLastProduct.apply, (X, Y1))  # a broadcast batch axis
    state = random_state(1, seed=8)
    x = state.mean.T.clone().requires_grad_(True)
    P = state.covariance.permute(1, 2, 0).clone().requires_grad_(True)
    Q = noise(None, seed=9)[0].unsqueeze(-1).requires_grad_(True)
    # the backward assumes P symmetric (as every covariance of the filter is): check it on symmetric P
    predict = lambda x_, P_, Q_: _PosePredict.apply(x_, 0.5 * (P_ + P_.transpose(0, 1)), Q_, 0.1)  # noqa: E731
    assert torch.autograd.gradcheck(predict, (x, P, Q), fast_mode=True)  # random directions: a few calls


def test_run_with_the_structured_step_equals_the_generic_run(monkeypatch: pytest.MonkeyPatch, prediction_path: str) -> None:
    """A whole batch, with sequences initialising at different steps, rows without a measurement
    at some steps and a quaternion sign flip: every output and the gradient."""
    batch, steps = 4, 14
    g = torch.Generator().manual_seed(10)
    truth = random_state(batch, seed=11).mean
    z = truth[:, None, :7] + 0.02 * torch.randn(batch, steps, 7, generator=g, dtype=torch.float64)
    z[1, 5:, :4] *= -1
    mask = torch.rand(batch, steps, generator=g) < 0.5
    mask[:, 3] = True
    mask[0, :4] = False
    base = NoiseParameters.from_std([0.01] * 13, [0.05] * 7, [0.1] * 13)
    filt = make_filter("ekf")

    def run(structured: bool):
        monkeypatch.setattr(ekf, "STRUCTURED_MIN_BATCH", 1 if structured else 10**9)
        monkeypatch.setattr(kernels, "ENABLED", structured and prediction_path == "kernels")  # generic: no kernel predict
        log_q = torch.full((13,), -4.0, dtype=torch.float64, requires_grad=True)
        noise = dataclasses.replace(base, process=torch.diag_embed(torch.exp(2 * log_q)))
        result = filt.run(noise, z, mask, dt=0.1)
        (gradient,) = torch.autograd.grad(result.means.square().sum() + result.covariances.sum(), log_q)
        return result, gradient

    (fast, g_fast), (dense, g_dense) = run(True), run(False)
    for name in ("means", "covariances", "innovations", "innovation_covariances", "prior_means"):
        torch.testing.assert_close(getattr(fast, name), getattr(dense, name), rtol=1e-11, atol=1e-13, msg=name)
    assert torch.equal(fast.updated, dense.updated) and torch.equal(fast.initialised, dense.initialised)
    torch.testing.assert_close(g_fast, g_dense, rtol=1e-10, atol=1e-13)
