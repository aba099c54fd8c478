"""Fixed-interval Rauch-Tung-Striebel smoothing of a filter's output, in error-state form.

H. E. Rauch, F. Tung & C. T. Striebel, "Maximum likelihood estimates of linear dynamic systems",
AIAA Journal 3(8), 1965; the error-state (multiplicative) form for an attitude follows J. Sola,
"Quaternion kinematics for the error-state Kalman filter", arXiv:1711.02508, 2017 (the backward
pass corrects the filtered nominal state with an error estimate, as the update does).

Given the filtered posteriors ``x_k|k`` (means, ``(B, T, n)``) and ``P_k|k`` (error covariances,
``(B, T, k, k)``) of a filter whose prediction is ``x_k+1|k = f(x_k|k)`` with error transition
``Phi_k`` and process noise ``Q`` (``P_k+1|k = Phi_k P_k|k Phi_k^T + Q``), the backward pass from
``x^s_T-1 = x_T-1|T-1`` is, for ``k = T - 2 .. 0``:

    G_k   = P_k|k Phi_k^T P_k+1|k^-1                     (a linear solve, no inverse)
    dx_k  = G_k (x^s_k+1 [-] x_k+1|k)
    x^s_k = x_k|k [+] dx_k
    P^s_k = P_k|k + G_k (P^s_k+1 - P_k+1|k) G_k^T        (symmetrised)

with ``[+]`` / ``[-]`` the state's composition with an error and its inverse (additive for a
vector state; :func:`pose_correct` / :func:`pose_difference` for a pose ``[q, r, w, v, ...]``
whose attitude error is the world-frame ``dtheta`` of ``q_true = exp(dtheta / 2) (x) q``).
``Phi_k`` and ``x_k+1|k`` are recomputed from the stored posterior means (the filter stores no
transition). For a linear-Gaussian model this is the exact fixed-interval smoother: the posterior
mean and covariance of each state given all the measurements.

Segments: the recursion runs within runs of linked steps. ``linked[b, k]`` says that step
``k + 1`` of sequence ``b`` was predicted from step ``k`` (then maybe updated); where it was not
(before a sequence initialised, at an initialisation or re-initialisation from a measurement),
step ``k`` ends a segment and is smoothed from itself (``x^s_k = x_k|k``), and steps outside any
initialised segment keep what the filter reports.

numpy float64, batched over sequences (the backward loop runs over time, each step one batched
solve over the linked rows).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from fkn_bench.geometry import quaternion as qx
from fkn_bench.linalg import symmetrize
from fkn_bench.models.base import StateSpaceModel
from fkn_bench.models.error_state import error_transition
from fkn_bench.types import ArrayB, ArrayF, Bool, Float

__all__ = ["rts_smooth", "smooth_pose", "pose_difference", "pose_correct"]

Transition = Callable[[ArrayF, float], tuple[ArrayF, ArrayF]]
"""``(x (N, n), dt) -> (x' (N, n), Phi (N, k, k))``: the prediction and its error transition."""


def pose_difference(a: Float[ArrayF, "N n"], b: Float[ArrayF, "N n"]) -> Float[ArrayF, "N n-1"]:
    """``a [-] b``: the error ``[dtheta, a[4:] - b[4:]]`` with ``q_a = exp(dtheta / 2) (x) q_b``
    (world frame, rad; the shorter of the two rotations ``q_a`` and ``-q_a`` give)."""
    dtheta = qx.to_rotation_vector(qx.multiply(a[:, 0:4], qx.conjugate(b[:, 0:4])))
    return np.concatenate((dtheta, a[:, 4:] - b[:, 4:]), axis=1)


def pose_correct(x: Float[ArrayF, "N n"], dx: Float[ArrayF, "N n-1"]) -> Float[ArrayF, "N n"]:
    """``x [+] dx``: ``q <- exp(dtheta / 2) (x) q`` (renormalised), the other components plus
    ``dx[3:]``."""
    q = qx.multiply(qx.from_rotation_vector(dx[:, 0:3]), x[:, 0:4])
    q = q / np.sqrt((q * q).sum(1, keepdims=True))
    return np.concatenate((q, x[:, 4:] + dx[:, 3:]), axis=1)


def rts_smooth(
    means: Float[ArrayF, "B T n"],
    covariances: Float[ArrayF, "B T k k"],
    process_noise: Float[ArrayF, "k k"] | Float[ArrayF, "B k k"],
    dt: float,
    *,
    transition: Transition,
    difference: Callable[[ArrayF, ArrayF], ArrayF] = np.subtract,
    correct: Callable[[ArrayF, ArrayF], ArrayF] = np.add,
    linked: Bool[ArrayB, "B T-1"] | None = None,
) -> tuple[Float[ArrayF, "B T n"], Float[ArrayF, "B T k k"]]:
    """The RTS smoother's means ``(B, T, n)`` and covariances ``(B, T, k, k)`` (module docstring).

    Args:
        means, covariances: the filter's posteriors ``x_k|k`` and ``P_k|k`` (error covariances
            for a state with an error parameterisation).
        process_noise: ``Q`` ``(k, k)``, or one per sequence ``(B, k, k)``.
        dt: step length, s.
        transition: ``(x (N, n), dt) -> (x_next (N, n), Phi (N, k, k))``.
        difference: ``[-]`` on ``(N, n)`` states -> ``(N, k)`` errors (default: subtraction).
        correct: ``[+]`` of ``(N, n)`` states and ``(N, k)`` errors (default: addition).
        linked: ``(B, T - 1)``, True where step ``k + 1`` was predicted from step ``k``
            (default: everywhere).

    Raises ``numpy.linalg.LinAlgError`` where a predicted covariance is singular.
    """
    means = np.asarray(means, dtype=np.float64)
    covariances = np.asarray(covariances, dtype=np.float64)
    batch, steps, _ = means.shape
    k = covariances.shape[-1]
    Q = np.broadcast_to(np.asarray(process_noise, dtype=np.float64), (batch, k, k))
    if linked is None:
        linked = np.ones((batch, max(steps - 1, 0)), dtype=bool)
    linked = np.asarray(linked, dtype=bool)
    if linked.shape != (batch, max(steps - 1, 0)):
        raise ValueError(f"linked must have shape {(batch, max(steps - 1, 0))} (got {linked.shape})")
    smoothed_means, smoothed_covs = means.copy(), covariances.copy()
    for t in range(steps - 2, -1, -1):
        rows = np.flatnonzero(linked[:, t])
        if rows.size == 0:
            continue
        x, P = means[rows, t], covariances[rows, t]
        predicted, Phi = transition(x, dt)
        P_pred = symmetrize(Phi @ P @ Phi.swapaxes(1, 2) + Q[rows])
        gain = np.linalg.solve(P_pred, Phi @ P).swapaxes(1, 2)  # G = P Phi^T P_pred^-1 (P, P_pred symmetric)
        dx = (gain @ difference(smoothed_means[rows, t + 1], predicted)[..., None])[..., 0]
        smoothed_means[rows, t] = correct(x, dx)
        smoothed_covs[rows, t] = symmetrize(P + gain @ (smoothed_covs[rows, t + 1] - P_pred) @ gain.swapaxes(1, 2))
    return smoothed_means, smoothed_covs


def smooth_pose(
    model: StateSpaceModel,
    means: Float[ArrayF, "B T n"],
    covariances: Float[ArrayF, "B T n-1 n-1"],
    process_noise: Float[ArrayF, "n-1 n-1"],
    dt: float,
    *,
    linked: Bool[ArrayB, "B T-1"] | None = None,
) -> tuple[Float[ArrayF, "B T n"], Float[ArrayF, "B T n-1 n-1"]]:
    """:func:`rts_smooth` of a pose model's error-state filter (the multiplicative EKF): the
    transition :func:`fkn_bench.models.error_state.error_transition`, the attitude composed as
    ``exp(dtheta / 2) (x) q`` (:func:`pose_correct`, :func:`pose_difference`)."""
    return rts_smooth(means, covariances, process_noise, dt, transition=lambda x, step: error_transition(model, x, step),
                      difference=pose_difference, correct=pose_correct, linked=linked)
