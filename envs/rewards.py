"""The reward of the Astrobee environments: minus a weighted error of the state estimate.

``reward = -(theta + w_r |r_est - r| + w_w |w_est - w| + w_v |v_est - v|)`` where ``theta`` is
the attitude error angle (rad, sign-safe: ``q`` and ``-q`` score the same; the estimate's
quaternion is normalised first) and ``|.|`` the Euclidean norm. Default weights
(:data:`DEFAULT_WEIGHTS`): 1 per rad, 1 per m, 10 per rad/s and 10 per m/s, so that typical
errors of a good filter on ds1 (about 0.05 rad, 0.03 m, 0.002 rad/s, 0.002 m/s) weigh alike.

The angle uses ``|a - b| = 2 sin(theta/4)`` and ``|a + b| = 2 cos(theta/4)`` for unit
quaternions with ``a . b >= 0``: ``theta = 4 atan2(min |a -+ b|, max |a -+ b|)``, accurate at
small angles and indifferent to sign. Both quaternions are normalised the same way, so an
estimate equal to the truth (or to its negative) scores exactly 0, even where the true
quaternion is unit only to rounding.

Two implementations with the same operation order: :func:`estimate_cost` (numpy, batched; its
component-major form :func:`estimate_cost_components`) and
:func:`estimate_cost_scalar` (Python floats, for the single environment's fast path). They agree
bit for bit, which keeps the vector environment's rewards identical to single environments'.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from fkn_bench.types import ArrayF, Float

__all__ = ["DEFAULT_WEIGHTS", "WEIGHT_LIMIT", "estimate_cost", "estimate_cost_components", "estimate_cost_scalar", "attitude_error_angle", "unit_quaternions", "cost_and_quaternion_norm"]

DEFAULT_WEIGHTS: Mapping[str, float] = {"attitude": 1.0, "position": 1.0, "omega": 10.0, "velocity": 10.0}

WEIGHT_LIMIT = 1e6
"""Largest reward weight the environments accept: with it and actions within
:data:`~fkn_bench.envs.spaces.ACTION_LIMIT`, the cost stays below about 1e157, always finite."""


def _chords(e: Sequence, t: Sequence, sqrt: Callable) -> tuple:
    """``|u - v|`` and ``|u + v|`` for ``u``, ``v`` the normalised estimate ``e`` and truth ``t``
    (components 0-3: rows of transposed batches with ``np.sqrt``, or floats with ``math.sqrt``)."""
    e0, e1, e2, e3 = e[0], e[1], e[2], e[3]
    t0, t1, t2, t3 = t[0], t[1], t[2], t[3]
    norm = sqrt(e0 * e0 + e1 * e1 + e2 * e2 + e3 * e3)
    u0, u1, u2, u3 = e0 / norm, e1 / norm, e2 / norm, e3 / norm
    norm = sqrt(t0 * t0 + t1 * t1 + t2 * t2 + t3 * t3)
    t0, t1, t2, t3 = t0 / norm, t1 / norm, t2 / norm, t3 / norm
    m0, m1, m2, m3 = u0 - t0, u1 - t1, u2 - t2, u3 - t3
    p0, p1, p2, p3 = u0 + t0, u1 + t1, u2 + t2, u3 + t3
    return sqrt(m0 * m0 + m1 * m1 + m2 * m2 + m3 * m3), sqrt(p0 * p0 + p1 * p1 + p2 * p2 + p3 * p3)


def attitude_error_angle(q_true: Float[ArrayF, "N 4"], q_est: Float[ArrayF, "N 4"]) -> Float[ArrayF, "N"]:
    """Rotation angle (rad) between attitudes ``(N, 4)``; neither need be exactly unit."""
    minus, plus = _chords(q_est.T, q_true.T, np.sqrt)
    return 4.0 * np.arctan2(np.minimum(minus, plus), np.maximum(minus, plus))


def estimate_cost(truth: Float[ArrayF, "N 13"], estimate: Float[ArrayF, "N 13"],
                  weights: Mapping[str, float] = DEFAULT_WEIGHTS) -> Float[ArrayF, "N"]:
    """Weighted error (>= 0) of estimates ``(N, 13)`` against the truth ``(N, 13)``: ``(N,)``."""
    return estimate_cost_components(truth.T, estimate.T, weights)


def estimate_cost_components(
    truth: Float[ArrayF, "13 N"], estimate: Float[ArrayF, "13 N"], weights: Mapping[str, float] = DEFAULT_WEIGHTS, *,
    unit_truth: Float[ArrayF, "4 N"] | None = None,
) -> Float[ArrayF, "N"]:
    """:func:`estimate_cost` of component-major ``(13, N)`` truth and estimates, computed
    block-wise (a dozen numpy calls on ``(4, N)`` and ``(9, N)`` blocks; a sum over the component
    axis adds the rows in order, as the scalar form does). ``unit_truth (4, N)``: the normalised
    true quaternions, if already computed (:func:`unit_quaternions`)."""
    return cost_and_quaternion_norm(truth, estimate, weights, unit_truth=unit_truth)[0]


def cost_and_quaternion_norm(
    truth: Float[ArrayF, "13 N"], estimate: Float[ArrayF, "13 N"], weights: Mapping[str, float] = DEFAULT_WEIGHTS, *,
    unit_truth: Float[ArrayF, "4 N"] | None = None,
) -> tuple[Float[ArrayF, "N"], Float[ArrayF, "N"]]:
    """:func:`estimate_cost_components` and the squared norms ``(N,)`` of the estimates'
    quaternions (which the vector environment checks against zero)."""
    q = estimate[:4]
    norm2 = (q * q).sum(axis=0)
    u = q / np.sqrt(norm2)
    t = unit_quaternions(truth) if unit_truth is None else unit_truth
    m, p = u - t, u + t
    m *= m
    p *= p
    minus, plus = np.sqrt(m.sum(axis=0)), np.sqrt(p.sum(axis=0))
    parts = np.empty((4, q.shape[1]))  # angle and the three norms, weighted, then added in that order
    np.arctan2(np.minimum(minus, plus), np.maximum(minus, plus), out=parts[0])
    parts[0] *= 4.0
    d = estimate[4:] - truth[4:]
    d *= d
    np.sqrt(d.reshape(3, 3, -1).sum(axis=1), out=parts[1:])
    parts *= np.array([weights["attitude"], weights["position"], weights["omega"], weights["velocity"]])[:, None]
    return parts.sum(axis=0), norm2


def unit_quaternions(states: ArrayF) -> ArrayF:
    """The quaternions of component-major states ``(13, N)`` (or ``(4, N)``), normalised as the
    cost normalises them: ``(4, N)``."""
    q = states[:4]
    return q / np.sqrt((q * q).sum(axis=0))


def estimate_cost_scalar(
    truth: Sequence[float], estimate: Sequence[float], weights: Mapping[str, float] = DEFAULT_WEIGHTS
) -> float:
    """:func:`estimate_cost` for one 13-element truth and estimate (lists of floats)."""
    minus, plus = _chords(estimate, truth, math.sqrt)
    # numpy's arctan2, not math.atan2: the two may differ in the last bit
    angle = 4.0 * float(np.arctan2(min(minus, plus), max(minus, plus)))
    d = [estimate[i] - truth[i] for i in range(4, 13)]
    return (
        weights["attitude"] * angle
        + weights["position"] * math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        + weights["omega"] * math.sqrt(d[3] * d[3] + d[4] * d[4] + d[5] * d[5])
        + weights["velocity"] * math.sqrt(d[6] * d[6] + d[7] * d[7] + d[8] * d[8])
    )
