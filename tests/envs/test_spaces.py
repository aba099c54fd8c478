"""Observation and action spaces, the NaN-aware pose type, and action validation."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium import spaces

from fkn_bench.envs.spaces import (
    POSITION_LIMIT,
    RATE_LIMIT,
    MeasuredPose,
    PoseBox,
    action_space,
    observation_space,
    pose_space,
    validate_actions,
)

POSE = np.array([0.5, 0.5, -0.5, 0.5, 10.9, -6.7, 4.9])
MISSING = np.full(7, np.nan)


def test_pose_box_accepts_poses_and_missing_rows() -> None:
    box = pose_space()
    assert isinstance(box, PoseBox) and box.shape == (7,) and box.dtype == np.float64
    np.testing.assert_array_equal(box.high, [1, 1, 1, 1, POSITION_LIMIT, POSITION_LIMIT, POSITION_LIMIT])
    np.testing.assert_array_equal(box.low, -box.high)
    assert box.contains(POSE)
    assert box.contains(MISSING)
    assert box.contains(list(POSE))
    assert box.contains(box.sample())
    assert "NaN" in repr(box)


@pytest.mark.parametrize(
    "pose",
    [
        np.array([np.nan, 0, 0, 1.0, 0, 0, 0]),  # partly missing
        np.array([1.0, 0, 0, 0, 2 * POSITION_LIMIT, 0, 0]),  # out of bounds
        np.array([1.5, 0, 0, 0, 0, 0, 0]),
        np.zeros(6),  # wrong shape
        np.zeros((1, 7)),
        "pose",
        [[1.0, 2.0], [3.0]],
    ],
)
def test_pose_box_rejects(pose: object) -> None:
    assert not pose_space().contains(pose)


def test_batched_pose_box() -> None:
    box = pose_space(3)
    assert box.shape == (3, 7)
    batch = np.stack([POSE, MISSING, POSE])
    assert box.contains(batch)
    batch[2, 0] = np.nan
    assert not box.contains(batch)
    assert not box.contains(np.stack([POSE, POSE]))


def test_measured_pose_nan_equality() -> None:
    a = MISSING.copy().view(MeasuredPose)
    b = MISSING.copy().view(MeasuredPose)
    assert np.all(a == b) and not np.any(a != b)
    assert np.allclose(a, b) and np.array_equal(a, b)
    assert np.all(np.isclose(a, MISSING))
    # a plain array would not compare equal
    assert not np.any(MISSING == MISSING)
    p = POSE.copy().view(MeasuredPose)
    assert np.all(p == POSE) and not np.any(p != POSE)
    assert not np.any(p == a)
    assert not np.allclose(p, a)
    q = POSE.copy()
    q[0] += 0.1
    assert not np.array_equal(p, q)
    # behaves as a float64 array otherwise
    assert p.dtype == np.float64 and p.shape == (7,)
    np.testing.assert_array_equal(np.asarray(p) * 2, POSE * 2)
    assert p.__hash__ is None


def test_observation_space() -> None:
    space = observation_space(n_steps=50, dt=0.1)
    assert isinstance(space, spaces.Dict) and set(space.spaces) == {"pose", "valid", "time"}
    assert space["valid"] == spaces.Discrete(2)
    assert space["time"].shape == () and space["time"].high == pytest.approx(5.0)
    assert space.contains({"pose": MISSING, "valid": np.int64(0), "time": np.array(0.1)})
    assert not space.contains({"pose": POSE, "valid": np.int64(1), "time": np.array(6.0)})


def test_action_space() -> None:
    space = action_space()
    assert space.shape == (13,) and space.dtype == np.float64
    np.testing.assert_array_equal(space.high, [1.0] * 4 + [POSITION_LIMIT] * 3 + [RATE_LIMIT] * 6)
    np.testing.assert_array_equal(space.low, -space.high)


def test_validate_actions_accepts_and_converts() -> None:
    action = np.concatenate([POSE, np.zeros(6)])
    out = validate_actions(action)
    assert out.dtype == np.float64 and out.shape == (13,)
    np.testing.assert_array_equal(out, action)
    np.testing.assert_array_equal(validate_actions(action.astype(np.float32).tolist()), action.astype(np.float32))
    batch = validate_actions(np.tile(action, (4, 1)), batch=4)
    assert batch.shape == (4, 13)
    # an unnormalised quaternion is fine
    validate_actions(np.concatenate([[0.0, 0.0, 3.0, 0.0], np.zeros(9)]))


@pytest.mark.parametrize(
    ("action", "batch", "pattern"),
    [
        (np.zeros(12), None, r"shape \(13,\) \(got \(12,\)\)"),
        (np.zeros((1, 13)), None, r"shape \(13,\) \(got \(1, 13\)\)"),
        (np.zeros((3, 13)), 4, r"shape \(4, 13\) \(got \(3, 13\)\)"),
        (np.zeros(13), 4, r"shape \(4, 13\) \(got \(13,\)\)"),
        ("abc", None, r"float array of shape \(13,\)"),
        ([1.0, [2.0]], None, r"float array of shape \(13,\)"),
    ],
)
def test_validate_actions_shape_errors(action: object, batch: int | None, pattern: str) -> None:
    with pytest.raises(ValueError, match=pattern):
        validate_actions(action, batch=batch)


def test_validate_actions_non_finite_names_component() -> None:
    action = np.concatenate([POSE, np.zeros(6)])
    action[8] = np.nan
    with pytest.raises(ValueError, match=r"action must be finite: action\[8\] \(wy\) is nan"):
        validate_actions(action)
    action[8] = 0.0
    action[1] = np.inf
    with pytest.raises(ValueError, match=r"action\[1\] \(qx\) is inf"):
        validate_actions(action)
    batch = np.tile(np.concatenate([POSE, np.zeros(6)]), (3, 1))
    batch[2, 11] = -np.inf
    with pytest.raises(ValueError, match=r"action\[2, 11\] \(vy\) is -inf"):
        validate_actions(batch, batch=3)


def test_validate_actions_zero_quaternion() -> None:
    with pytest.raises(ValueError, match="quaternion .* zero norm"):
        validate_actions(np.zeros(13))
    batch = np.tile(np.concatenate([POSE, np.zeros(6)]), (3, 1))
    batch[1, :4] = 1e-7
    with pytest.raises(ValueError, match="zero norm"):
        validate_actions(batch, batch=3)
