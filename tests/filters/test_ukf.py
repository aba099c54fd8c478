"""The UKF: sigma-point weights, exactness on linear models (against the plain KF), the
unscented mean of the paper's bilinear model, and the null-direction regularisation."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import fkn_bench.filters.ukf as ukf_module
from fkn_bench.envs import generate_episodes
from fkn_bench.filters import FilterState, UnscentedKalmanFilter, make_filter
from fkn_bench.models import LinearGaussianModel, NoiseParameters
from fkn_bench.filters.linear import linear_kalman_filter
from fkn_bench.filters.ukf import sigma_point_weights

DT = 0.1


@pytest.mark.parametrize(("n", "alpha", "beta", "kappa"), [(13, 1.0, 2.0, 0.0), (4, 0.5, 2.0, 1.0), (3, 1e-3, 0.0, 0.0)])
def test_sigma_point_weights(n: int, alpha: float, beta: float, kappa: float) -> None:
    scale, wm, wc = sigma_point_weights(n, alpha, beta, kappa)
    lam = alpha**2 * (n + kappa) - n
    assert scale == pytest.approx(np.sqrt(n + lam))
    assert wm.shape == wc.shape == (2 * n + 1,)
    assert float(wm.sum()) == pytest.approx(1.0, abs=1e-9)
    assert float(wc.sum()) == pytest.approx(2.0 - alpha**2 + beta, abs=1e-9)
    # the points reproduce a covariance exactly: sum_i W_i (s L_i)(s L_i)^T over +- = L L^T
    assert float(2 * wm[1] * scale**2) == pytest.approx(1.0)
    with pytest.raises(ValueError, match=r"alpha\^2 \(n \+ kappa\) must be > 0"):
        sigma_point_weights(n, alpha, beta, -float(n))


def test_default_weights_are_non_negative() -> None:
    variant = UnscentedKalmanFilter()
    assert (variant._wm >= 0).all() and variant._scale == pytest.approx(np.sqrt(13.0))


def _linear_problem(seed: int):
    rng = np.random.default_rng(seed)
    A = np.eye(4)
    A[0, 2] = A[1, 3] = DT
    H = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])
    Q = np.diag([1e-3, 2e-3, 1e-2, 3e-2])
    R = np.array([[0.25, 0.05], [0.05, 0.09]])
    P0 = np.diag([1.0, 2.0, 3.0, 4.0]) + 0.1
    x0 = rng.standard_normal((3, 4))
    z = rng.standard_normal((3, 150, 2)) + np.linspace(0, 5, 150)[None, :, None]
    mask = rng.random((3, 150)) < 0.5
    mask[:, 0] = True
    mask[1, :25] = False
    z[~mask] = np.nan
    return A, H, Q, R, P0, x0, z, mask


@pytest.mark.parametrize("alpha", [1.0, 0.3])
def test_ukf_equals_linear_kalman_filter(alpha: float) -> None:
    """On a linear model the unscented transform is exact: the UKF reproduces the plain KF to
    1e-12 (measured: a few 1e-15)."""
    A, H, Q, R, P0, x0, z, mask = _linear_problem(int(alpha * 10))
    variant = UnscentedKalmanFilter(model=LinearGaussianModel(torch.from_numpy(A), torch.from_numpy(H)), alpha=alpha)
    noise = NoiseParameters(torch.from_numpy(Q), torch.from_numpy(R), torch.from_numpy(P0))
    initial = FilterState(torch.from_numpy(x0), torch.from_numpy(P0).expand(3, 4, 4))
    result = variant.run(noise, torch.from_numpy(z), torch.from_numpy(mask), dt=DT, initial=initial)
    for b in range(3):
        means, covariances = linear_kalman_filter(A, H, Q, R, x0[b], P0, np.nan_to_num(z[b]), mask[b])
        np.testing.assert_allclose(result.means[b].numpy(), means, rtol=0, atol=1e-12)
        np.testing.assert_allclose(result.covariances[b].numpy(), covariances, rtol=0, atol=1e-12)


def test_unscented_mean_of_the_bilinear_pose_model_is_exact() -> None:
    """``q' = q + dt/2 Omega(w) q`` is bilinear in (q, w), so its mean under a Gaussian is
    ``f(mean) + dt/2 sum_ab Cov(w_a, q_b) Omega(e_a) e_b``; the unscented transform captures it."""
    rng = np.random.default_rng(4)
    x = rng.standard_normal(13)
    x[:4] /= np.linalg.norm(x[:4])
    L = 0.1 * rng.standard_normal((13, 13))
    P = L @ L.T + 1e-3 * np.eye(13)
    variant = UnscentedKalmanFilter()
    predicted = variant.predict(FilterState(torch.from_numpy(x)[None], torch.from_numpy(P)[None]), torch.zeros(13, 13, dtype=torch.float64), DT)
    expected = variant.model.predict(torch.from_numpy(x)[None], DT)[0].numpy()
    for a in range(3):
        w = np.zeros(3)
        w[a] = 1.0
        omega = np.array([[0, -w[0], -w[1], -w[2]], [w[0], 0, -w[2], w[1]], [w[1], w[2], 0, -w[0]], [w[2], -w[1], w[0], 0]])
        expected[:4] += 0.5 * DT * omega @ P[7 + a, :4]
    np.testing.assert_allclose(predicted.mean[0].numpy(), expected, rtol=0, atol=1e-14)
    # the mean is not f(mean) here: the test is sensitive to the correction
    assert np.abs(expected - variant.model.predict(torch.from_numpy(x)[None], DT)[0].numpy()).max() > 1e-5


def test_singular_posterior_covariance_needs_no_fallback(monkeypatch: pytest.MonkeyPatch) -> None:
    """After a pose update P is singular along q; the null-direction term keeps the Cholesky
    factorisation from failing, in float64 and in float32 (where a fixed 1e-10 was too small and
    the isotropic fallback inflated every small variance)."""
    failures = {"calls": 0, "failed": 0}
    original = ukf_module._safe_cholesky

    def counting(P: torch.Tensor) -> torch.Tensor:
        failures["calls"] += 1
        failures["failed"] += int((torch.linalg.cholesky_ex(P)[1] != 0).sum())
        return original(P)

    monkeypatch.setattr(ukf_module, "_safe_cholesky", counting)
    episodes = generate_episodes("ds1", [0, 1], split="train").window(0, 300)
    variant = make_filter("ukf")
    z, mask = torch.from_numpy(episodes.measurements), torch.from_numpy(episodes.valid)
    results = {}
    for dtype in (torch.float64, torch.float32):
        results[dtype] = variant.run(variant.layout.default_noise(), z.to(dtype), mask, dt=DT)
        assert failures["calls"] == 299 and failures["failed"] == 0, (dtype, failures)
        failures.update(calls=0, failed=0)
    torch.testing.assert_close(results[torch.float32].means.double(), results[torch.float64].means, rtol=0, atol=2e-4)


def test_safe_cholesky_fallback_is_finite() -> None:
    P = torch.tensor([[[1.0, 1.0], [1.0, 1.0 - 1e-17]], [[2.0, 0.0], [0.0, 3.0]]], dtype=torch.float64)
    L = ukf_module._safe_cholesky(P)
    assert torch.isfinite(L).all()
    # untouched row; exact: a diagonal matrix, L = diag(sqrt 2, sqrt 3) (correctly rounded sqrt)
    torch.testing.assert_close(L[1], torch.linalg.cholesky(P[1]), rtol=0, atol=0)
    torch.testing.assert_close(L[0] @ L[0].T, P[0], rtol=0, atol=1e-6)
