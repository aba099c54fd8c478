"""The reward's cost: known values, sign safety, small-angle accuracy, and the bit-for-bit
agreement of the batched and the scalar implementation."""

from __future__ import annotations

import numpy as np
import pytest

from fkn_bench.envs.rewards import DEFAULT_WEIGHTS, attitude_error_angle, estimate_cost, estimate_cost_scalar
from fkn_bench.geometry import quaternion as quat


def _random_states(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    truth = rng.standard_normal((n, 13))
    truth[:, :4] /= np.linalg.norm(truth[:, :4], axis=1, keepdims=True)
    estimate = truth + 0.1 * rng.standard_normal((n, 13))
    # estimates with arbitrary quaternion norm and sign, a few of them far off
    estimate[:, :4] *= rng.uniform(0.2, 3.0, (n, 1)) * rng.choice([-1.0, 1.0], (n, 1))
    estimate[::7, :4] = rng.standard_normal((len(estimate[::7]), 4))
    return truth, estimate


def test_default_weights() -> None:
    assert dict(DEFAULT_WEIGHTS) == {"attitude": 1.0, "position": 1.0, "omega": 10.0, "velocity": 10.0}


def test_cost_known_value() -> None:
    truth = np.zeros((1, 13))
    truth[0, :4] = quat.IDENTITY
    estimate = truth.copy()
    estimate[0, :4] = quat.from_rotation_vector([0.0, 0.0, np.pi / 2])  # 90 degrees
    estimate[0, 4:7] += [3.0, 4.0, 0.0]  # 5 m
    estimate[0, 7:10] += [0.0, 0.0, 0.1]  # 0.1 rad/s
    estimate[0, 10:13] += [0.0, -0.06, 0.08]  # 0.1 m/s
    expected = np.pi / 2 + 5.0 + 10 * 0.1 + 10 * 0.1
    np.testing.assert_allclose(estimate_cost(truth, estimate), [expected], rtol=1e-15)
    assert estimate_cost_scalar(truth[0].tolist(), estimate[0].tolist()) == pytest.approx(expected, rel=1e-15)
    weights = {"attitude": 2.0, "position": 0.5, "omega": 0.0, "velocity": 1.0}
    expected_w = 2 * np.pi / 2 + 0.5 * 5.0 + 0.0 + 1.0 * 0.1
    np.testing.assert_allclose(estimate_cost(truth, estimate, weights), [expected_w], rtol=1e-15)


def test_cost_matches_independent_formula() -> None:
    rng = np.random.default_rng(0)
    truth, estimate = _random_states(rng, 2000)
    expected = (
        quat.angle_between(truth[:, :4], quat.normalize(estimate[:, :4]))
        + np.linalg.norm(estimate[:, 4:7] - truth[:, 4:7], axis=1)
        + 10 * np.linalg.norm(estimate[:, 7:10] - truth[:, 7:10], axis=1)
        + 10 * np.linalg.norm(estimate[:, 10:13] - truth[:, 10:13], axis=1)
    )
    np.testing.assert_allclose(estimate_cost(truth, estimate), expected, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize(
    "weights", [DEFAULT_WEIGHTS, {"attitude": 0.3, "position": 7.0, "omega": 1e-3, "velocity": 2.5}]
)
def test_batched_and_scalar_agree_bit_for_bit(weights: dict) -> None:
    rng = np.random.default_rng(1)
    truth, estimate = _random_states(rng, 3000)
    batched = estimate_cost(truth, estimate, weights)
    scalar = np.array([estimate_cost_scalar(t, e, weights) for t, e in zip(truth.tolist(), estimate.tolist())])
    # exact by design: the same correctly rounded + - * sqrt in the same order, min/max, and the same
    # numpy arctan2 kernel for a 1-element and an n-element contiguous array (SVML lanes or libm,
    # element-wise either way; checked with numpy's AVX512 and AVX2/baseline dispatch)
    assert batched.tobytes() == scalar.tobytes()


def test_perfect_estimate_costs_exactly_zero() -> None:
    rng = np.random.default_rng(2)
    truth, _ = _random_states(rng, 500)
    # the true quaternion of a simulation is unit only to rounding
    truth[:, :4] *= 1.0 + rng.choice([-2.0, -1.0, 0.0, 1.0, 2.0], (500, 1)) * np.finfo(float).eps
    negated = truth.copy()
    negated[:, :4] *= -1.0
    for estimate in (truth, negated):
        # exact: equal (or exactly negated) operands give minus = 0 and differences 0, atan2(0, x) = 0
        np.testing.assert_array_equal(estimate_cost(truth, estimate), 0.0)
        assert all(estimate_cost_scalar(t, e) == 0.0 for t, e in zip(truth.tolist(), estimate.tolist()))


def test_attitude_error_angle_sign_safe() -> None:
    rng = np.random.default_rng(3)
    truth, estimate = _random_states(rng, 1000)
    q_true, q_est = truth[:, :4], estimate[:, :4]
    angle = attitude_error_angle(q_true, q_est)
    # exact: negating a quaternion only swaps |q1 - q2| and |q1 + q2| (sign-symmetric rounding), which
    # min/max undo: the same atan2 operands
    np.testing.assert_array_equal(attitude_error_angle(q_true, -q_est), angle)
    np.testing.assert_array_equal(attitude_error_angle(-q_true, q_est), angle)
    np.testing.assert_array_equal(attitude_error_angle(q_true, 2.5 * q_est) >= 0, True)
    np.testing.assert_allclose(attitude_error_angle(q_true, 2.5 * q_est), angle, rtol=1e-14, atol=1e-15)
    assert np.all((angle >= 0) & (angle <= np.pi))


def test_attitude_error_angle_large_angles() -> None:
    q_true = np.tile(quat.IDENTITY, (4, 1))
    angles = np.array([np.pi / 3, np.pi / 2, np.pi - 1e-6, np.pi])
    q_est = quat.from_rotation_vector(angles[:, None] * np.array([0.0, 0.6, 0.8]))
    np.testing.assert_allclose(attitude_error_angle(q_true, q_est), angles, rtol=1e-14)


@pytest.mark.parametrize("angle", [1e-10, 1e-8, 1e-6, 1e-4, 1e-2])
def test_attitude_error_angle_small_angles(angle: float) -> None:
    """Accurate where ``2 arccos(q_true . q_est)`` collapses to 0 (below ~1e-8 rad)."""
    rng = np.random.default_rng(4)
    q_true = quat.random_uniform(rng, 200)
    axes = rng.standard_normal((200, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    q_est = quat.multiply(quat.from_rotation_vector(angle * axes), q_true)
    reference = np.linalg.norm(quat.error_rotation_vector(q_est, q_true), axis=1)
    result = attitude_error_angle(q_true, q_est)
    # both are limited by the rounding of q_est itself (~1e-16 absolute)
    np.testing.assert_allclose(result, reference, rtol=1e-6, atol=2e-15)
    np.testing.assert_allclose(result, angle, rtol=1e-6, atol=2e-15)
