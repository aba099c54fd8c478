"""Conversions between the 13-dim state covariance and the 12-dim error covariance, and pose
innovations."""

from __future__ import annotations

import numpy as np

from fkn_bench.filters.pose import error_covariance_from_state, pose_innovation, state_covariance_from_error
from fkn_bench.geometry import quaternion as quat


def _unit_quaternions(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.standard_normal((n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _spd(rng: np.random.Generator, n: int, k: int) -> np.ndarray:
    L = rng.standard_normal((n, k, k))
    return L @ np.swapaxes(L, 1, 2) + 0.1 * np.eye(k)


def test_error_to_state_and_back_is_the_identity() -> None:
    rng = np.random.default_rng(0)
    q = _unit_quaternions(rng, 5)
    E = _spd(rng, 5, 12)
    P = state_covariance_from_error(q, E)
    assert P.shape == (5, 13, 13)
    np.testing.assert_allclose(error_covariance_from_state(q, P), E, rtol=0, atol=1e-12)
    # the state covariance has no variance along q itself (unit-norm constraint)
    np.testing.assert_allclose(np.einsum("bi,bij,bj->b", q, P[:, :4, :4], q), 0.0, atol=1e-12)
    # other blocks pass through unchanged, up to the symmetrisation of the result: exact on any
    # machine, as the block is E copied (products with 1 and 0 only) and then 0.5 (E + E^T) here and
    # there (E = L L^T itself may be asymmetric in the last bit, depending on the BLAS)
    E_symmetric = 0.5 * (E + np.swapaxes(E, -1, -2))
    np.testing.assert_allclose(P[:, 4:, 4:], E_symmetric[:, 3:, 3:], rtol=0, atol=0)
    # batch of batches broadcasts
    assert error_covariance_from_state(q.reshape(5, 1, 4), P.reshape(5, 1, 13, 13)).shape == (5, 1, 12, 12)


def test_state_to_error_drops_only_the_radial_direction() -> None:
    rng = np.random.default_rng(1)
    q = _unit_quaternions(rng, 4)
    P = _spd(rng, 4, 13)
    radial = np.zeros((4, 13))
    radial[:, :4] = q
    P_plus = P + 7.0 * np.einsum("bi,bj->bij", radial, radial)  # variance along q is invisible
    np.testing.assert_allclose(error_covariance_from_state(q, P_plus), error_covariance_from_state(q, P), rtol=0, atol=1e-12)


def test_quaternion_map_matches_small_rotations() -> None:
    """``dtheta = 2 Theta(q)^T dq`` for ``q_true = exp(dtheta / 2) (x) q`` (world-frame error)."""
    rng = np.random.default_rng(2)
    q = _unit_quaternions(rng, 6)
    dtheta = 1e-6 * rng.standard_normal((6, 3))
    q_true = quat.multiply(quat.from_rotation_vector(dtheta), q)
    dq = q_true - q
    # pose_innovation applies the same map to a 7-dim [dq, dr] innovation
    nu7 = np.concatenate((dq, rng.standard_normal((6, 3))), axis=1)
    nu6, S6 = pose_innovation(q, nu7, np.broadcast_to(np.eye(7), (6, 7, 7)))
    np.testing.assert_allclose(nu6[:, :3], dtheta, rtol=0, atol=1e-12)
    # exact: the position rows of T are identity rows (one product with 1, the rest with 0), and
    # symmetrising the exact identity block gives it back
    np.testing.assert_allclose(nu6[:, 3:], nu7[:, 4:], rtol=0, atol=0)
    np.testing.assert_allclose(quat.error_rotation_vector(q_true, q), dtheta, rtol=0, atol=1e-12)
    # for a unit q, 2 Theta^T (2 Theta^T)^T = 4 I: an isotropic quaternion variance s^2 is 4 s^2 rad^2
    np.testing.assert_allclose(S6[:, :3, :3], np.broadcast_to(4.0 * np.eye(3), (6, 3, 3)), rtol=0, atol=1e-14)
    np.testing.assert_allclose(S6[:, 3:, 3:], np.broadcast_to(np.eye(3), (6, 3, 3)), rtol=0, atol=0)
