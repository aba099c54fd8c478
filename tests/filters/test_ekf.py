"""The EKF: against the plain KF on a linear model, against filterpy's EKF on the paper's model,
sign alignment and the Joseph form. (The long run on hostile data, 3e4 steps, is in
tests/baselines/test_long_run.py, with the manual and the tuned parameters in one batch.)"""

from __future__ import annotations

import numpy as np
import pytest
import torch
from filterpy.kalman import ExtendedKalmanFilter as FilterpyEKF

from fkn_bench.envs import generate_episodes
from fkn_bench.filters import ExtendedKalmanFilter, FilterState, make_filter
from fkn_bench.models import LinearGaussianModel, PoseTwistModel
from fkn_bench.filters.ekf import joseph_update
from fkn_bench.filters.linear import linear_kalman_filter
from fkn_bench.filters.pose import error_covariance_from_state
from fkn_bench.geometry.quaternion import angle_between
from fkn_bench.scenarios import get_scenario

DT = 0.1


# ---------------------------------------------------------------------------- the linear case
def linear_problem(seed: int, batch: int = 3, steps: int = 150):
    """Constant-velocity model in 2-D (state [px, py, vx, vy]) with position-only measurements,
    about half of them missing (NaN)."""
    rng = np.random.default_rng(seed)
    A = np.eye(4)
    A[0, 2] = A[1, 3] = DT
    H = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])
    Q = np.diag([1e-3, 2e-3, 1e-2, 3e-2])
    R = np.array([[0.25, 0.05], [0.05, 0.09]])
    P0 = np.diag([1.0, 2.0, 3.0, 4.0]) + 0.1
    x0 = rng.standard_normal((batch, 4))
    z = rng.standard_normal((batch, steps, 2)) + np.linspace(0, 5, steps)[None, :, None]
    mask = rng.random((batch, steps)) < 0.5
    mask[:, 0] = True
    mask[0, :20] = False  # a long gap at the start of one sequence
    z[~mask] = np.nan
    return A, H, Q, R, P0, x0, z, mask


@pytest.mark.parametrize("seed", [0, 1])
def test_ekf_equals_linear_kalman_filter(seed: int) -> None:
    A, H, Q, R, P0, x0, z, mask = linear_problem(seed)
    variant = ExtendedKalmanFilter(model=LinearGaussianModel(torch.from_numpy(A), torch.from_numpy(H)))
    noise = type(variant.layout.default_noise())(torch.from_numpy(Q), torch.from_numpy(R), torch.from_numpy(P0))
    initial = FilterState(torch.from_numpy(x0), torch.from_numpy(P0).expand(len(x0), 4, 4))
    result = variant.run(noise, torch.from_numpy(z), torch.from_numpy(mask), dt=DT, initial=initial)
    for b in range(len(x0)):
        means, covariances = linear_kalman_filter(A, H, Q, R, x0[b], P0, np.nan_to_num(z[b]), mask[b])
        np.testing.assert_allclose(result.means[b].numpy(), means, rtol=0, atol=1e-12)
        np.testing.assert_allclose(result.covariances[b].numpy(), covariances, rtol=0, atol=1e-12)
    assert result.updated.numpy().tolist() == mask.tolist()


def test_joseph_update_with_dense_H_equals_sliced_H() -> None:
    rng = np.random.default_rng(2)
    n, m, batch = 13, 7, 4
    L = rng.standard_normal((batch, n, n))
    P = torch.from_numpy(L @ L.transpose(0, 2, 1) + np.eye(n))
    x = torch.from_numpy(rng.standard_normal((batch, n)))
    nu = torch.from_numpy(rng.standard_normal((batch, m)))
    R = torch.from_numpy(np.diag(rng.uniform(0.1, 1.0, m)))
    H = torch.cat((torch.eye(m), torch.zeros(m, n - m)), dim=1).double()
    model = PoseTwistModel()
    for normalize in (None, model.normalize):
        sliced = joseph_update(x, P, nu, R, observed=slice(0, m), normalize=normalize)
        dense = joseph_update(x, P, nu, R, H=H, normalize=normalize)
        for a, b in zip(sliced, dense):
            torch.testing.assert_close(a, b, rtol=0, atol=1e-12)
    # without normalisation the Joseph form equals the textbook (I - KH) P for the optimal gain
    x_post, P_post, S, _ = joseph_update(x, P, nu, R, H=H)
    K = P @ H.T @ torch.linalg.inv(S)
    torch.testing.assert_close(P_post, (torch.eye(n, dtype=torch.float64) - K @ H) @ P, rtol=0, atol=1e-10)
    torch.testing.assert_close(x_post, x + (K @ nu[..., None])[..., 0], rtol=0, atol=1e-12)


def test_predict_covariance_uses_the_autograd_jacobian() -> None:
    rng = np.random.default_rng(3)
    x = rng.standard_normal((2, 13))
    x[:, :4] /= np.linalg.norm(x[:, :4], axis=1, keepdims=True)
    L = rng.standard_normal((2, 13, 13))
    state = FilterState(torch.from_numpy(x), torch.from_numpy(L @ L.transpose(0, 2, 1)))
    variant = ExtendedKalmanFilter()
    Q = variant.layout.default_noise().process
    predicted = variant.predict(state, Q, DT)
    for b in range(2):
        F = torch.autograd.functional.jacobian(lambda s: variant.model.predict(s[None], DT)[0], state.mean[b])
        torch.testing.assert_close(predicted.covariance[b], F @ state.covariance[b] @ F.T + Q, rtol=0, atol=1e-12)
        # not exact: a (2, 13) batch against a single row, whose products BLAS may run with other
        # kernels (gemm/gemv, FMA or not): |mean| < 3.5, a few roundings of ulp(3.5) = 4.4e-16
        torch.testing.assert_close(predicted.mean[b], variant.model.predict(state.mean[b : b + 1], DT)[0], rtol=0, atol=2e-15)


# ---------------------------------------------------------------------------- filterpy
def _theta(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array([[-x, -y, -z], [w, z, -y], [-z, w, x], [y, -x, w]])


def _paper_f(x: np.ndarray) -> np.ndarray:
    out = x.copy()
    out[0:4] = x[0:4] + 0.5 * DT * _theta(x[0:4]) @ x[7:10]
    out[4:7] = x[4:7] + DT * x[10:13]
    return out


def _paper_F(x: np.ndarray) -> np.ndarray:
    """FlexKalmanNet's F written out here: d(Theta(q) w)/dq = Omega(w), d/dw = Theta(q)."""
    wx, wy, wz = x[7:10]
    omega = np.array([[0, -wx, -wy, -wz], [wx, 0, -wz, wy], [wy, wz, 0, -wx], [wz, -wy, wx, 0]])
    F = np.eye(13)
    F[0:4, 0:4] += 0.5 * DT * omega
    F[0:4, 7:10] = 0.5 * DT * _theta(x[0:4])
    F[4:7, 10:13] = DT * np.eye(3)
    return F


class _PaperEKF(FilterpyEKF):
    """filterpy's EKF with the paper's nonlinear f in the mean prediction (filterpy's own
    predict_x would apply x = F x)."""

    def predict_x(self, u=0):  # noqa: ANN001, ANN201 (filterpy's signature)
        self.x = _paper_f(self.x[:, 0])[:, None]


def test_ekf_agrees_with_filterpy_step_by_step() -> None:
    """1000 steps of ds1 with a measurement every 10 steps, to 1e-9.

    filterpy is made to compute the same thing: the paper's f for the mean and F (set before
    each predict) for the covariance; filterpy's update is the Joseph form
    ``(I - KH) P (I - KH)' + K R K'``; the measured quaternion is normalised and sign-aligned with
    the prediction beforehand; afterwards the state quaternion is renormalised and the
    covariance projected with ``T = blockdiag((I - u u') / |q|, I9)`` and symmetrised. Our EKF
    merges the Joseph form and the projection into one product, which is algebraically the same.
    """
    episodes = generate_episodes("ds1", [3], split="train").window(0, 1000)
    z_all, valid = episodes.measurements[0], episodes.valid[0]
    assert valid.sum() == 100
    variant = make_filter("ekf")
    noise = variant.layout.default_noise()
    x0 = np.concatenate((episodes.truth[0, 0, :7], [0.01, -0.02, 0.03, 0.0, 0.0, 0.0]))
    P0 = noise.initial.numpy()
    result = variant.run(
        noise,
        torch.from_numpy(z_all)[None],
        torch.from_numpy(valid)[None],
        dt=DT,
        initial=FilterState(torch.from_numpy(x0)[None], torch.from_numpy(P0)[None]),
    )
    H = np.hstack((np.eye(7), np.zeros((7, 6))))
    reference = _PaperEKF(dim_x=13, dim_z=7)
    reference.x, reference.P = x0[:, None].copy(), P0.copy()
    reference.Q, reference.R = noise.process.numpy(), noise.measurement.numpy()
    worst_mean = worst_cov = 0.0
    for t in range(len(z_all)):
        if t > 0:
            reference.F = _paper_F(reference.x[:, 0])
            reference.predict()
        if valid[t]:
            z = z_all[t].copy()
            z[:4] /= np.linalg.norm(z[:4])
            if z[:4] @ reference.x[:4, 0] < 0:
                z[:4] = -z[:4]
            reference.update(z[:, None], lambda x: H, lambda x: H @ x)
            q = reference.x[:4, 0]
            norm = np.linalg.norm(q)
            unit = q / norm
            T = np.eye(13)
            T[:4, :4] = (np.eye(4) - np.outer(unit, unit)) / norm
            reference.x[:4, 0] = unit
            reference.P = T @ reference.P @ T.T
            reference.P = 0.5 * (reference.P + reference.P.T)
        worst_mean = max(worst_mean, np.abs(result.means[0, t].numpy() - reference.x[:, 0]).max())
        worst_cov = max(worst_cov, np.abs(result.covariances[0, t].numpy() - reference.P).max())
    assert worst_mean < 1e-9 and worst_cov < 1e-9, (worst_mean, worst_cov)
    assert result.updated[0].sum() == 100


# ---------------------------------------------------------------------------- sign alignment
class _NoAlignModel(PoseTwistModel):
    def align(self, z: torch.Tensor, x_pred: torch.Tensor) -> torch.Tensor:
        return z


def test_measured_quaternion_sign_is_aligned_before_the_innovation() -> None:
    clean = generate_episodes("ds1", [0, 1], split="train").window(0, 600)
    flipped = generate_episodes(get_scenario("ds1", sign_flip_probability=0.5), [0, 1], split="train").window(0, 600)
    # common random numbers: the flipped data differ only in the signs
    signs = np.sign(np.sum(clean.measurements[..., :4] * flipped.measurements[..., :4], axis=-1))
    assert (signs[clean.valid] == -1).mean() > 0.3
    # exact: the same seeded draws and arithmetic; the flips only negate (exact) the quaternions
    np.testing.assert_array_equal(np.abs(clean.measurements[clean.valid]), np.abs(flipped.measurements[clean.valid]))
    mask = torch.from_numpy(clean.valid)
    aligned = ExtendedKalmanFilter()
    noise = aligned.layout.default_noise()
    reference = aligned.run(noise, torch.from_numpy(clean.measurements), mask, dt=DT).means.numpy()
    estimates = aligned.run(noise, torch.from_numpy(flipped.measurements), mask, dt=DT).means.numpy()
    # exact on any IEEE machine: the aligned measurements are identical, and where the state starts
    # from a flipped measurement every quaternion-dependent intermediate is exactly negated
    # (round-to-nearest is sign-symmetric)
    np.testing.assert_array_equal(estimates[..., 4:], reference[..., 4:])
    np.testing.assert_array_equal(np.abs(estimates[..., :4]), np.abs(reference[..., :4]))
    truth = clean.truth[..., :4]
    error = angle_between(estimates[:, 100:, :4], truth[:, 100:])
    assert np.sqrt(np.mean(error**2)) < 0.12  # rad: it tracks (measurement noise ~0.17 rad)

    # without the alignment, the same flipped data wreck the filter
    naive = ExtendedKalmanFilter(model=_NoAlignModel())
    broken = naive.run(noise, torch.from_numpy(flipped.measurements), mask, dt=DT).means.numpy()
    error = angle_between(broken[:, 100:, :4], truth[:, 100:])
    assert np.sqrt(np.mean(error**2)) > 0.5
    assert np.abs(broken[:, 100:, 7:10]).max() > 0.5  # the rate estimate is thrown around (true |w| < 0.08)
    # ...while on unflipped data the naive filter is fine: the alignment is what matters
    fine = naive.run(noise, torch.from_numpy(clean.measurements), mask, dt=DT).means.numpy()
    np.testing.assert_allclose(fine, reference, rtol=0, atol=1e-12)


# ---------------------------------------------------------------------------- Joseph form
def test_posterior_covariances_symmetric_psd_and_unit_quaternions() -> None:
    episodes = generate_episodes("ds1-flips", [0, 1], split="train").window(0, 800)
    variant = ExtendedKalmanFilter()
    noise = variant.layout.default_noise()
    # an aggressive (tiny) R: a hard case for the covariance update (gains near one)
    noise = type(noise)(noise.process, noise.measurement * 1e-8, noise.initial)
    result = variant.run(noise, torch.from_numpy(episodes.measurements), torch.from_numpy(episodes.valid), dt=DT)
    P = result.covariances.numpy()
    means = result.means.numpy()
    updated = result.updated.numpy()
    # posteriors are symmetrised exactly; predictions F P F' + Q are symmetric to rounding
    # exact on any machine: 0.5 (P + P^T) holds the same sum of the same two numbers at [i, j] and
    # [j, i] (IEEE addition is commutative)
    np.testing.assert_array_equal(P[updated], np.swapaxes(P[updated], -1, -2))
    np.testing.assert_allclose(P, np.swapaxes(P, -1, -2), rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(means[updated][:, :4], axis=-1), 1.0, rtol=0, atol=1e-14)
    eigenvalues = np.linalg.eigvalsh(P[result.initialised.numpy()])
    scale = eigenvalues.max(-1, keepdims=True)
    assert (eigenvalues >= -1e-14 * scale).all()
    # after an update the 13x13 covariance is singular exactly along the state quaternion
    Pq = P[updated]
    q = means[updated][:, :4]
    np.testing.assert_allclose(np.einsum("bi,bij,bj->b", q, Pq[:, :4, :4], q), 0.0, atol=1e-18)
    error = error_covariance_from_state(means[updated][:, :4], Pq)
    assert np.linalg.eigvalsh(error).min() > 0
