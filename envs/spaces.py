"""Observation and action spaces of the Astrobee environments, and validation of actions.

A missing measurement is a pose of seven NaN. Two pieces make that first-class in Gymnasium:

* :class:`PoseBox`, a ``Box`` whose ``contains`` also accepts an all-NaN pose (a missing
  measurement), so the passive checker does not flag valid observations;
* :class:`MeasuredPose`, the float64 ``ndarray`` subclass the environments return for poses: it
  behaves as a plain array except that two missing (NaN) entries compare equal under ``==``,
  ``np.allclose``, ``np.isclose`` and ``np.array_equal``. Gymnasium's ``check_env`` compares the
  observations of two identically seeded runs with ``np.allclose`` and ``==``; with plain NaN,
  every missing measurement would read as non-determinism.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces

from fkn_bench.inputs import real_array
from fkn_bench.types import STATE_DIM, STATE_NAMES, ArrayF

__all__ = [
    "ACTION_LIMIT",
    "action_values",
    "MeasuredPose",
    "QUATERNION_NORM_MIN",
    "PoseBox",
    "POSITION_LIMIT",
    "RATE_LIMIT",
    "pose_space",
    "observation_space",
    "action_space",
    "validate_actions",
]

POSITION_LIMIT = 1.0e3
"""Bound of position observations and estimates, m (the ISS is about 110 m across)."""
RATE_LIMIT = 10.0
"""Bound of angular-rate (rad/s) and velocity (m/s) estimates."""

_NAN_EQUAL_FUNCTIONS = {np.isclose, np.allclose, np.array_equal}


class MeasuredPose(np.ndarray):
    """A float64 pose array where NaN marks a missing measurement (see module docstring)."""

    def __eq__(self, other: Any) -> Any:  # type: ignore[override]
        mine, theirs = np.asarray(self), np.asarray(other)
        return np.equal(mine, theirs) | (np.isnan(mine) & np.isnan(theirs))

    def __ne__(self, other: Any) -> Any:  # type: ignore[override]
        return ~self.__eq__(other)

    __hash__ = None  # type: ignore[assignment]

    def __array_function__(self, func: Any, types: Any, args: Any, kwargs: Any) -> Any:
        if func in _NAN_EQUAL_FUNCTIONS:
            kwargs = {**kwargs, "equal_nan": True}
        return super().__array_function__(func, types, args, kwargs)


class PoseBox(spaces.Box):
    """A ``Box`` of poses ``[qw, qx, qy, qz, rx, ry, rz]`` (last axis) in which a pose of all
    NaN, a missing measurement, is also a member."""

    def contains(self, x: Any) -> bool:
        if not isinstance(x, np.ndarray):
            try:
                x = np.asarray(x, dtype=self.dtype)
            except (ValueError, TypeError):
                return False
        if x.shape != self.shape:
            return False
        missing = np.isnan(x).all(axis=-1, keepdims=True)
        return super().contains(np.where(missing, 0.0, x).astype(self.dtype))

    def __repr__(self) -> str:
        return f"PoseBox({self.shape}, {self.dtype}, NaN rows = missing)"


def pose_space(batch: int | None = None) -> PoseBox:
    """Space of one pose ``(7,)`` or of a batch ``(batch, 7)``."""
    high = np.array([1.0] * 4 + [POSITION_LIMIT] * 3)
    if batch is not None:
        high = np.tile(high, (batch, 1))
    return PoseBox(low=-high, high=high, dtype=np.float64)


def observation_space(n_steps: int, dt: float) -> spaces.Dict:
    """The single-environment observation space: pose, validity flag and time (s)."""
    return spaces.Dict(
        {
            "pose": pose_space(),
            "valid": spaces.Discrete(2),
            "time": spaces.Box(low=0.0, high=float(n_steps * dt), shape=(), dtype=np.float64),
        }
    )


QUATERNION_NORM_MIN = 1e-12
"""Smallest squared norm of an action's quaternion that can be scored (normalised)."""

ACTION_LIMIT = 1e150
"""Largest magnitude of an action's component that is scored: beyond it, the squares that the
reward takes (the quaternion's norm, the error norms) could overflow float64. Refused with a
``ValueError`` (an estimate of 1e150 m is a bug, not an estimate); within it, and with reward
weights of at most :data:`~fkn_bench.envs.rewards.WEIGHT_LIMIT`, every reward is finite."""


def action_space() -> spaces.Box:
    """The single-environment action space: a 13-dim state estimate in SI units.

    The quaternion need not be unit (it is normalised for scoring); bounds are descriptive
    (1 for quaternion components, :data:`POSITION_LIMIT` m, :data:`RATE_LIMIT` rad/s and m/s):
    what ``step`` refuses is :func:`validate_actions`'s rule (beyond :data:`ACTION_LIMIT`).
    """
    high = np.array([1.0] * 4 + [POSITION_LIMIT] * 3 + [RATE_LIMIT] * 6)
    return spaces.Box(low=-high, high=high, dtype=np.float64)


def action_values(action: Any) -> list[float]:
    """One environment's action as a list of 13 floats, validated as :func:`validate_actions`
    does (same errors), with a fast path for the usual float64 ``(13,)`` array: the single
    environment's step costs a few microseconds, and numpy's checks would dominate it."""
    if type(action) is np.ndarray and action.shape == (STATE_DIM,) and action.dtype == np.float64:
        values = action.tolist()
        if (all(map(math.isfinite, values)) and max(map(abs, values)) <= ACTION_LIMIT
                and sum(v * v for v in values[:4]) >= QUATERNION_NORM_MIN):
            return values
    return validate_actions(action).tolist()


def validate_actions(actions: Any, batch: int | None = None) -> ArrayF:
    """Return ``actions`` as float64 ``(13,)`` (or ``(batch, 13)``) or raise ``ValueError``.

    The rules, in this order (the first broken one is named):

    * numbers of a real integer or floating dtype, exactly of that shape
      (:func:`fkn_bench.inputs.real_array`: strings, bools, complex numbers, objects, values
      beyond float64's range, ragged nestings, 0-d arrays and extra axes are refused);
    * every entry finite, and within ``+-ACTION_LIMIT`` (:data:`ACTION_LIMIT`), naming the
      offending component;
    * a quaternion of squared norm at least :data:`QUATERNION_NORM_MIN` (it is normalised for
      scoring; its scale is otherwise free).
    """
    expected = (STATE_DIM,) if batch is None else (batch, STATE_DIM)
    array = real_array(actions, "action", expected)
    finite = np.isfinite(array)
    if not finite.all():
        bad = np.argwhere(~finite)[0]
        where = f"action[{', '.join(str(int(i)) for i in bad)}]"
        raise ValueError(
            f"action must be finite: {where} ({STATE_NAMES[int(bad[-1])]}) is {array[tuple(bad)]}"
        )
    beyond = np.abs(array) > ACTION_LIMIT
    if beyond.any():
        bad = np.argwhere(beyond)[0]
        where = f"action[{', '.join(str(int(i)) for i in bad)}]"
        raise ValueError(
            f"action must be within +-ACTION_LIMIT = {ACTION_LIMIT:g}: {where} ({STATE_NAMES[int(bad[-1])]}) is "
            f"{array[tuple(bad)]:g} (its reward would overflow float64)"
        )
    norm2 = np.sum(array[..., :4] ** 2, axis=-1)
    if np.any(norm2 < QUATERNION_NORM_MIN):
        raise ValueError("action quaternion action[..., 0:4] has zero norm; cannot score the attitude")
    return array
