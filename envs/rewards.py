"""The reward of the Astrobee environments: minus a weighted error of the state estimate.

``reward = -(theta + w_r |r_est - r| + w_w |w_est - w| + w_v |v_est - v|)`` where ``theta`` is
the attitude error angle (rad, sign-safe: ``q`` and ``-q`` score the same, the estimate's
quaternion is normalised first) and ``|.|`` the Euclidean norm. Default weights
(:data:`DEFAULT_WEIGHTS`): 1 per rad, 1 per m, 10 per rad/s and 10 per m/s, so that typical
errors of a good filter on ds1 (about 0.05 rad, 0.03 m, 0.002 rad/s, 0.002 m/s) weigh alike.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from fkn_bench.types import ArrayF

__all__ = ["DEFAULT_WEIGHTS", "estimate_cost", "attitude_error_angle"]

DEFAULT_WEIGHTS: Mapping[str, float] = {"attitude": 1.0, "position": 1.0, "omega": 10.0, "velocity": 10.0}


def attitude_error_angle(q_true: ArrayF, q_est: ArrayF) -> ArrayF:
    """Rotation angle (rad) between attitudes, ``(..., 4)`` inputs, sign-safe and accurate at 0.

    For unit ``a``, ``b`` at rotation angle ``theta``: ``|a - b| = 2 sin(theta/4)`` and
    ``|a + b| = 2 cos(theta/4)`` when ``a . b >= 0``; taking the smaller of ``|a -+ b|`` picks the
    sign. ``q_est`` is normalised here.
    """
    q_est = q_est / np.sqrt(np.sum(q_est * q_est, axis=-1, keepdims=True))
    minus = np.sqrt(np.sum((q_est - q_true) ** 2, axis=-1))
    plus = np.sqrt(np.sum((q_est + q_true) ** 2, axis=-1))
    return 4.0 * np.arctan2(np.minimum(minus, plus), np.maximum(minus, plus))


def estimate_cost(truth: ArrayF, estimate: ArrayF, weights: Mapping[str, float] = DEFAULT_WEIGHTS) -> ArrayF:
    """Weighted error (>= 0) of 13-dim estimates against the truth, ``(..., 13)`` -> ``(...)``."""
    diff = estimate[..., 4:] - truth[..., 4:]
    sq = diff * diff
    return (
        weights["attitude"] * attitude_error_angle(truth[..., :4], estimate[..., :4])
        + weights["position"] * np.sqrt(np.sum(sq[..., 0:3], axis=-1))
        + weights["omega"] * np.sqrt(np.sum(sq[..., 3:6], axis=-1))
        + weights["velocity"] * np.sqrt(np.sum(sq[..., 6:9], axis=-1))
    )
