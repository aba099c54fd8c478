"""Component errors, group error magnitudes and the 12-dim error state on constructed cases."""

from __future__ import annotations

import numpy as np
import pytest

from fkn_bench.geometry import quaternion as quat
from fkn_bench.metrics import attitude_error_deg, component_errors, error_state, group_errors


def _states(B: int = 2, T: int = 5, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(B, T, 13))
    x[..., :4] = quat.normalize(x[..., :4])
    return x


def test_sign_flipped_quaternion_is_no_error() -> None:
    truth = _states()
    estimate = truth.copy()
    estimate[..., :4] *= -1.0  # the same attitude
    assert np.allclose(attitude_error_deg(truth[..., :4], estimate[..., :4]), 0.0, atol=1e-6)
    assert np.allclose(component_errors(truth, estimate), 0.0)
    assert np.allclose(error_state(truth, estimate), 0.0, atol=1e-12)
    assert np.allclose(group_errors(truth, estimate)["attitude"], 0.0, atol=1e-6)


def test_known_rotation_angle() -> None:
    truth = _states()
    rotation = quat.from_rotation_vector(np.array([0.0, 0.0, np.radians(30.0)]))
    estimate = truth.copy()
    estimate[..., :4] = quat.multiply(rotation, truth[..., :4])
    assert np.allclose(attitude_error_deg(truth[..., :4], estimate[..., :4]), 30.0)
    estimate[..., :4] *= -1.0
    assert np.allclose(attitude_error_deg(truth[..., :4], estimate[..., :4]), 30.0)


def test_error_state_convention() -> None:
    """q_true = exp(dtheta/2) (x) q_est, the rest truth - estimate."""
    truth = _states()
    dtheta = np.array([0.01, -0.02, 0.03])
    estimate = truth.copy()
    estimate[..., :4] = quat.multiply(quat.conjugate(quat.from_rotation_vector(dtheta)), truth[..., :4])
    estimate[..., 4:] -= np.arange(1, 10) * 0.1
    e = error_state(truth, estimate)
    assert e.shape == (2, 5, 12)
    assert np.allclose(e[..., :3], dtheta)
    assert np.allclose(e[..., 3:], np.arange(1, 10) * 0.1)


def test_constant_offsets_give_group_norms() -> None:
    truth = _states()
    estimate = truth.copy()
    estimate[..., 4:7] += [0.3, 0.0, 0.4]
    estimate[..., 7:10] += [0.0, 0.01, 0.0]
    estimate[..., 10:13] -= [0.002, 0.0, 0.0]
    g = group_errors(truth, estimate)
    assert np.allclose(g["position"], 0.5)
    assert np.allclose(g["omega"], 0.01)
    assert np.allclose(g["velocity"], 0.002)
    assert np.allclose(g["attitude"], 0.0, atol=1e-6)
    e = component_errors(truth, estimate)
    assert np.allclose(e[..., 4:7], [0.3, 0.0, 0.4])


def test_half_turn_reads_180_degrees() -> None:
    truth = _states(1, 1)
    estimate = truth.copy()
    estimate[..., :4] = quat.multiply(np.array([0.0, 1.0, 0.0, 0.0]), truth[..., :4])
    assert attitude_error_deg(truth[..., :4], estimate[..., :4]) == pytest.approx(180.0)


def test_shape_mismatch_is_rejected() -> None:
    with pytest.raises(ValueError, match="shape"):
        component_errors(np.zeros((1, 3, 13)), np.zeros((1, 4, 13)))
    with pytest.raises(ValueError, match="13"):
        group_errors(np.zeros((1, 3, 12)), np.zeros((1, 3, 12)))
