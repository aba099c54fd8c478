"""The rigid-body model's compiled kernels: the single-trajectory propagation and the numpy
transition against the model's batched transition, and their independence of the batch."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fkn_bench.geometry import quaternion as quat
from fkn_bench.models.rigid_body import RigidBodyModel, _coefficients_and_derivative, euler_coefficients
from fkn_bench.models.rigid_body_kernels import body_rates, integrate_samples
from fkn_bench.scenarios import ASTROBEE_INERTIA


def _start(batch: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(5)
    return quat.random_uniform(rng, batch), rng.normal(size=(batch, 3)) * 0.4


def test_body_rates_rotate_into_the_body_frame() -> None:
    q, w = _start(4)
    np.testing.assert_allclose(body_rates(q, w), quat.rotate(quat.conjugate(q), w), rtol=0, atol=1e-15)


def test_samples_follow_the_models_transition_and_do_not_depend_on_the_batch() -> None:
    """One sample of ``substeps`` RK4 steps is the model's transition (its quaternion
    renormalised), to rounding; each row alone gives the same bits as in the batch."""
    q, w = _start(3)
    p = np.array([euler_coefficients(ASTROBEE_INERTIA)] * 3)
    y = np.concatenate((q, body_rates(q, w)), axis=1)
    q_out, w_out = np.empty((6, 4, 3)), np.empty((6, 3, 3))
    integrate_samples(y.copy(), p, 0.05, 2, False, q_out, w_out)
    model = RigidBodyModel(inertia=ASTROBEE_INERTIA, substeps=2)
    x = np.zeros((3, 13))
    x[:, 0:4], x[:, 7:10] = q, w
    for i in range(1, 6):
        x = model.predict(x, 0.1)
        x[:, 0:4] /= np.linalg.norm(x[:, 0:4], axis=1, keepdims=True)
        np.testing.assert_allclose(q_out[i].T, x[:, 0:4], rtol=0, atol=1e-14)
        np.testing.assert_allclose(w_out[i].T, x[:, 7:10], rtol=0, atol=1e-14)
    q_row, w_row = np.empty((6, 4, 1)), np.empty((6, 3, 1))
    integrate_samples(y[1:2].copy(), p[1:2], 0.05, 2, False, q_row, w_row)
    np.testing.assert_array_equal(q_row[:, :, 0], q_out[:, :, 1])
    np.testing.assert_array_equal(w_row[:, :, 0], w_out[:, :, 1])


def _rows(model: RigidBodyModel) -> np.ndarray:
    """Five states, their quaternions off unit norm (as between updates); row 3 spins at about
    22 rad/s (its step is refined) and, with ratios, row 0's ``p_y`` lies outside ``[-1, 1]``
    (clipped)."""
    rng = np.random.default_rng(11)
    x = 0.3 * rng.normal(size=(5, model.state_dim))
    x[:, 0:4] = quat.random_uniform(rng, 5) * rng.uniform(0.95, 1.05, size=(5, 1))
    x[3, 7:10] = (20.0, -5.0, 9.0)
    if model.estimate_ratios:
        x[0, 13:15] = (3.0, -2.0)
    return x


@pytest.mark.parametrize("model", [RigidBodyModel(inertia=ASTROBEE_INERTIA, substeps=2),
                                   RigidBodyModel(inertia=(1.0, 2.0, 2.5), estimate_ratios=True)], ids=["known", "ratios"])
def test_compiled_transition_is_the_torch_transition(model: RigidBodyModel) -> None:
    """Numpy input runs :func:`fkn_bench.models.rigid_body_kernels.transition`; a tensor under
    autograd the batched torch operations: mean and Jacobian agree to rounding, the refined
    and the clipped rows included. A CPU tensor without gradients takes the compiled path (same
    bits); the mean without the Jacobian is the same; a row's result does not depend on its batch."""
    x = _rows(model)
    assert 0.4 * np.linalg.norm(x[3, 7:10]) * 0.5 > model.substeps  # row 3 is refined
    if model.estimate_ratios:
        assert np.abs(_coefficients_and_derivative(x[:, 13:15])[0][0]).max() == 1.0  # row 0 is clipped
    mean, F = model.transition(x, 0.1)
    mean_t, F_t = model.transition(torch.from_numpy(x).requires_grad_(), 0.1)
    np.testing.assert_allclose(mean, mean_t.detach().numpy(), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(F, F_t.detach().numpy(), rtol=1e-12, atol=1e-12 * np.abs(F).max())
    with torch.no_grad():
        mean_n, F_n = model.transition(torch.from_numpy(x), 0.1)
    np.testing.assert_array_equal(mean_n.numpy(), mean)
    np.testing.assert_array_equal(F_n.numpy(), F)
    np.testing.assert_array_equal(model.predict(x, 0.1), mean)
    for row in (1, 4):
        alone, F_alone = model.transition(x[row:row + 1], 0.1)
        np.testing.assert_array_equal(alone[0], mean[row])
        np.testing.assert_array_equal(F_alone[0], F[row])
