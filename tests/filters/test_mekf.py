"""The multiplicative EKF: the SO(3) left Jacobian, the error transition against finite
differences and Monte Carlo, the update and reset, and sign invariance."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fkn_bench.envs import generate_episodes
from fkn_bench.filters import MEKF_MANUAL_LAYOUT, FilterState, MultiplicativeEKF, make_filter
from fkn_bench.filters.mekf import left_jacobian
from fkn_bench.geometry import quaternion as quat
from fkn_bench.geometry.quaternion import angle_between
from fkn_bench.types import ERROR_NAMES

DT = 0.1


def _log_of_exp_ratio(phi: np.ndarray, base: np.ndarray) -> np.ndarray:
    """``log(exp(phi) exp(base)^-1)`` as a rotation vector (numpy quaternions)."""
    return quat.to_rotation_vector(quat.multiply(quat.from_rotation_vector(phi), quat.conjugate(quat.from_rotation_vector(base))))


@pytest.mark.parametrize("angle", [0.0, 1e-5, 0.3, 1.5, 3.0])
def test_left_jacobian_is_the_derivative_of_the_exp_map(angle: float) -> None:
    """``exp(phi + d) = exp(J_l(phi) d) exp(phi)`` to first order in ``d``."""
    rng = np.random.default_rng(int(angle * 100))
    axis = rng.standard_normal(3)
    phi = angle * axis / np.linalg.norm(axis)
    J = left_jacobian(torch.from_numpy(phi)).numpy()
    h = 1e-6
    numeric = np.stack(
        [(_log_of_exp_ratio(phi + h * e, phi) - _log_of_exp_ratio(phi - h * e, phi)) / (2 * h) for e in np.eye(3)], axis=1
    )
    np.testing.assert_allclose(J, numeric, rtol=0, atol=1e-8)


def test_left_jacobian_branches_join_and_batch() -> None:
    """Either side of the small-angle switch (|phi| = 1e-4) the result matches the series to
    more terms, and the batch shape is kept."""
    phi = torch.tensor([[0.9999e-4, 0.0, 0.0], [0.0, 1.0001e-4, 0.0], [0.0, 0.0, 0.0], [0.1, -0.2, 0.3]], dtype=torch.float64)
    J = left_jacobian(phi)
    assert J.shape == (4, 3, 3)
    for row in range(3):
        a2 = float(phi[row] @ phi[row])
        c1 = 0.5 - a2 / 24.0 + a2**2 / 720.0
        c2 = 1.0 / 6.0 - a2 / 120.0 + a2**2 / 5040.0
        x, y, z = phi[row].tolist()
        K = torch.tensor([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]], dtype=torch.float64)  # [phi x]
        expected = torch.eye(3, dtype=torch.float64) + c1 * K + c2 * K @ K
        # above the switch, (1 - cos a) / a^2 loses ~eps / a^2 = 2e-8 of c1 to cancellation:
        # ~1e-12 after the product with [phi x] (|phi| = 1e-4)
        torch.testing.assert_close(J[row], expected, rtol=0, atol=1e-12)
    torch.testing.assert_close(J[2], torch.eye(3, dtype=torch.float64), rtol=0, atol=0)  # exact: phi = 0, I + c1 0 + c2 0
    # J_l(phi) phi = phi
    torch.testing.assert_close(J[3] @ phi[3], phi[3], rtol=0, atol=1e-15)


def _error_between(x_true: np.ndarray, x_nominal: np.ndarray) -> np.ndarray:
    """12-dim error ``[dtheta, dr, dw, dv]`` with ``q_true = exp(dtheta/2) (x) q_nominal``."""
    return np.concatenate((quat.error_rotation_vector(x_true[..., :4], x_nominal[..., :4]), x_true[..., 4:] - x_nominal[..., 4:]), axis=-1)


def _perturbed(x: np.ndarray, error: np.ndarray) -> np.ndarray:
    out = x.copy()
    out[..., :4] = quat.multiply(quat.from_rotation_vector(error[..., :3]), x[..., :4])
    out[..., 4:] = x[..., 4:] + error[..., 3:]
    return out


def _nominal_predict(variant: MultiplicativeEKF, x: np.ndarray) -> np.ndarray:
    P = torch.zeros(x.shape[0], 12, 12, dtype=torch.float64)
    state = variant.predict(FilterState(torch.from_numpy(x), P), torch.zeros(12, 12, dtype=torch.float64), DT)
    return state.mean.numpy()


def _state(seed: int, rate: float = 0.8) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x = rng.standard_normal(13)
    x[:4] /= np.linalg.norm(x[:4])
    x[7:10] *= rate
    return x


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_error_transition_against_finite_differences(seed: int) -> None:
    """Predicted covariance ``Phi P Phi' + Q`` with ``Phi`` the finite-difference Jacobian of
    the nominal prediction in error coordinates."""
    variant = MultiplicativeEKF()
    x = _state(seed)
    x_next = _nominal_predict(variant, x[None])[0]
    h = 1e-6
    columns = []
    for e in np.eye(12):
        plus = _nominal_predict(variant, _perturbed(x, h * e)[None])[0]
        minus = _nominal_predict(variant, _perturbed(x, -h * e)[None])[0]
        columns.append((_error_between(plus, x_next) - _error_between(minus, x_next)) / (2 * h))
    Phi = np.stack(columns, axis=1)
    rng = np.random.default_rng(100 + seed)
    L = rng.standard_normal((12, 12))
    P = L @ L.T
    Q = np.diag(rng.uniform(1e-4, 1e-2, 12))
    predicted = variant.predict(FilterState(torch.from_numpy(x)[None], torch.from_numpy(P)[None]), torch.from_numpy(Q), DT)
    np.testing.assert_allclose(predicted.covariance[0].numpy(), Phi @ P @ Phi.T + Q, rtol=0, atol=1e-7 * np.abs(P).max())
    # the mean is the exact rotation q' = exp(w dt / 2) (x) q
    np.testing.assert_allclose(x_next[:4], quat.multiply(quat.from_rotation_vector(DT * x[7:10]), x[:4]), rtol=0, atol=1e-15)


def test_predicted_covariance_matches_monte_carlo() -> None:
    variant = MultiplicativeEKF()
    x = _state(7, rate=2.0)  # a large rotation per step, where R(w dt) and J(w dt) matter
    rng = np.random.default_rng(8)
    L = 0.02 * rng.standard_normal((12, 12))
    P = L @ L.T + 1e-5 * np.eye(12)
    predicted = variant.predict(FilterState(torch.from_numpy(x)[None], torch.from_numpy(P)[None]), torch.zeros(12, 12, dtype=torch.float64), DT)
    samples = rng.multivariate_normal(np.zeros(12), P, size=40_000)
    moved = _nominal_predict(variant, _perturbed(np.broadcast_to(x, (len(samples), 13)), samples))
    errors = _error_between(moved, np.broadcast_to(predicted.mean[0].numpy(), moved.shape))
    empirical = np.cov(errors, rowvar=False)
    # whiten with the predicted covariance: sampling error of the entries ~ 1/sqrt(N) = 0.005
    whitening = np.linalg.inv(np.linalg.cholesky(predicted.covariance[0].numpy()))
    deviation = whitening @ empirical @ whitening.T - np.eye(12)
    assert np.abs(deviation).max() < 0.03, np.abs(deviation).max()
    assert np.abs(errors.mean(0) @ whitening.T).max() < 0.03  # and the error mean stays zero


def test_update_resets_to_a_unit_quaternion_with_full_rank_covariance() -> None:
    variant = MultiplicativeEKF()
    rng = np.random.default_rng(9)
    x = np.stack([_state(s) for s in range(4)])
    L = 0.1 * rng.standard_normal((4, 12, 12))
    P = L @ L.transpose(0, 2, 1) + 1e-3 * np.eye(12)
    truth_error = 0.05 * rng.standard_normal((4, 12))
    z = _perturbed(x, truth_error)[:, :7]
    z[1, :4] *= -1  # the sign of the measured quaternion does not matter
    R = torch.diag(torch.tensor([0.05] * 3 + [0.1] * 3, dtype=torch.float64) ** 2)
    state, nu, S = variant.update(FilterState(torch.from_numpy(x), torch.from_numpy(P)), torch.from_numpy(z), R)
    np.testing.assert_allclose(nu.numpy()[:, :3], quat.error_rotation_vector(z[:, :4], x[:, :4]), rtol=0, atol=1e-14)
    np.testing.assert_allclose(nu.numpy()[:, 3:], z[:, 4:7] - x[:, 4:7], rtol=0, atol=1e-15)
    np.testing.assert_allclose(S.numpy(), P[:, :6, :6] + R.numpy(), rtol=0, atol=1e-15)
    mean, covariance = state.mean.numpy(), state.covariance.numpy()
    np.testing.assert_allclose(np.linalg.norm(mean[:, :4], axis=1), 1.0, rtol=0, atol=1e-15)
    assert np.linalg.eigvalsh(covariance).min() > 0
    # the estimate moved from x towards the measurement: its error to z shrank
    before = np.linalg.norm(quat.error_rotation_vector(z[:, :4], x[:, :4]), axis=1)
    after = np.linalg.norm(quat.error_rotation_vector(z[:, :4], mean[:, :4]), axis=1)
    assert (after < before).all()
    # the error correction applied equals K nu (checked through the Kalman gain)
    K = P[:, :, :6] @ np.linalg.inv(S.numpy())
    dx = np.einsum("bij,bj->bi", K, nu.numpy())
    np.testing.assert_allclose(quat.error_rotation_vector(mean[:, :4], x[:, :4]), dx[:, :3], rtol=0, atol=1e-12)
    np.testing.assert_allclose(mean[:, 4:], x[:, 4:] + dx[:, 3:], rtol=0, atol=1e-14)


def test_layout_is_the_error_state() -> None:
    variant = MultiplicativeEKF()
    assert variant.layout is MEKF_MANUAL_LAYOUT
    assert (variant.covariance_dim, variant.innovation_dim) == (12, 6)
    assert MEKF_MANUAL_LAYOUT.q_labels == ERROR_NAMES and MEKF_MANUAL_LAYOUT.p0_labels == ERROR_NAMES
    assert MEKF_MANUAL_LAYOUT.r_labels == ERROR_NAMES[:3] + ("rx", "ry", "rz")
    # the paper's tuning mapped to the error state: 2x the quaternion-component stds
    assert MEKF_MANUAL_LAYOUT.r_default == (0.2,) * 3 + (0.1,) * 3
    assert MEKF_MANUAL_LAYOUT.q_default == (0.01,) * 3 + (1e-4,) * 3 + (0.005,) * 3 + (1e-4,) * 3


def test_mekf_is_sign_invariant_and_tracks_ds1() -> None:
    episodes = generate_episodes("ds1", [2], split="train").window(0, 500)
    variant = make_filter("mekf")
    noise = variant.layout.default_noise()
    z = torch.from_numpy(episodes.measurements)
    mask = torch.from_numpy(episodes.valid)
    flips = torch.from_numpy(np.random.default_rng(0).random(z.shape[:2]) < 0.5)
    flipped = z.clone()
    flipped[..., :4] = torch.where(flips[..., None], -z[..., :4], z[..., :4])
    reference = variant.run(noise, z, mask, dt=DT)
    result = variant.run(noise, flipped, mask, dt=DT)
    # exact on any IEEE machine: the aligned measurements are identical, and a state started from a
    # flipped measurement has every quaternion-dependent intermediate exactly negated
    # (round-to-nearest is sign-symmetric); the covariance does not depend on the sign at all
    torch.testing.assert_close(result.means[..., 4:], reference.means[..., 4:], rtol=0, atol=0)
    torch.testing.assert_close(result.means[..., :4].abs(), reference.means[..., :4].abs(), rtol=0, atol=0)
    torch.testing.assert_close(result.covariances, reference.covariances, rtol=0, atol=0)
    error = angle_between(reference.means[0, 100:, :4].numpy(), episodes.truth[0, 100:, :4])
    assert np.sqrt(np.mean(error**2)) < 0.12
    assert np.linalg.eigvalsh(reference.covariances[0].numpy()).min() > 0


def test_gradients_stay_finite_when_some_rows_skip_an_update() -> None:
    """A row without a usable measurement at a step where others update is filled with zeros
    before the masked update; its zero error quaternion must not put inf into the rotation vector,
    whose gradient through the mask would be NaN."""
    episodes = generate_episodes("ds1", [2, 3], split="train").window(0, 60)
    variant = make_filter("mekf")
    z = torch.from_numpy(episodes.measurements).clone()
    mask = torch.from_numpy(episodes.valid).clone()
    step = int(np.flatnonzero(mask[0].numpy() & mask[1].numpy())[3])
    z[1, step] = float("nan")  # row 1 skips this update, row 0 takes it
    noise = variant.layout.default_noise()
    R = noise.measurement.clone().requires_grad_(True)
    result = variant.run(type(noise)(noise.process, R, noise.initial), z, mask, dt=DT)
    result.means.sum().backward()
    assert R.grad is not None and torch.isfinite(R.grad).all()
