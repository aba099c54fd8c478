"""The rigid-body model's compiled single-trajectory propagation against the model's batched
transition, and its independence of the batch."""

from __future__ import annotations

import numpy as np

from fkn_bench.geometry import quaternion as quat
from fkn_bench.models.rigid_body import RigidBodyModel, euler_coefficients
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
