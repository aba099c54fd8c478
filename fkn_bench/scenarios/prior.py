"""The stated prior of a scenario as the first two moments of its initial error state.

The posterior Cramér-Rao bound (:mod:`fkn_bench.metrics.bound`) and the model-matched oracle
(:mod:`fkn_bench.estimators.matched`) need the truth's prior at step 0 as a mean and a covariance
of the error state ``[dtheta, dr, dw, dv(, dk)]`` (``fkn_bench/DESIGN.md``: world-frame attitude
error, rad; position, m; world-frame rate, rad/s; velocity, m/s; the two log inertia ratios ``k``
of :mod:`fkn_bench.models.rigid_body` when the inertia is uncertain). The prior is not Gaussian
(a uniform attitude, a log-uniform rate magnitude about a uniform axis, uniform inertia errors);
these are its exact second moments, so the bound computed from them is that of the Gaussian prior
with the same spread. Every component is independent of the others at step 0 (the draws come from
separate random streams) except the world-frame rate and the attitude when the rate is stated in
the body frame: their cross-covariance is zero by symmetry for a uniform attitude, and the rate's
covariance is then the body rate's averaged over attitudes.

Closed forms (``a``, ``b`` the magnitude range):

* uniform attitude on SO(3): ``E[|dtheta|^2] = pi^2 / 3 + 2`` (the rotation angle has density
  ``(1 - cos t) / pi`` on ``[0, pi]``), a third of it per axis;
* log-uniform magnitude: ``E[m] = (b - a) / ln(b / a)``, ``E[m^2] = (b^2 - a^2) / (2 ln(b / a))``;
  uniform: ``E[m] = (a + b) / 2``, ``E[m^2] = (a^2 + a b + b^2) / 3``;
* a uniform axis: ``Cov(m u) = E[m^2] / 3 I``; a fixed axis ``u``: ``Var(m) u u^T``;
* inertia errors ``J_i = J_i0 (1 + e_i)``, ``e_i ~ U(-s, s)``: ``k1 = ln(Jx / Jy)`` and
  ``k2 = ln(Jy / Jz)`` have covariance ``v [[2, -1], [-1, 2]]`` with ``v = Var(ln(1 + e))``,
  from ``int ln t dt = t ln t - t`` and ``int ln^2 t dt = t ln^2 t - 2 t ln t + 2 t``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fkn_bench.geometry import quaternion as quat
from fkn_bench.scenarios.scenario import Scenario
from fkn_bench.types import ArrayF

__all__ = ["ErrorPrior", "error_prior", "UNIFORM_ATTITUDE_VARIANCE", "magnitude_moments", "log_ratio_variance"]

UNIFORM_ATTITUDE_VARIANCE = (math.pi**2 / 3.0 + 2.0) / 3.0
"""Per-axis second moment of the rotation vector of a uniformly random attitude, rad^2 (1.76)."""


@dataclass(frozen=True)
class ErrorPrior:
    """Mean and covariance of a scenario's initial state in error coordinates.

    Attributes:
        rate_mean: mean world-frame rate (3,), rad/s (zero for a uniform axis or attitude).
        velocity_mean: mean velocity (3,), m/s.
        covariance: ``(n, n)`` covariance of ``[dtheta, dr, dw, dv]`` (n = 12) or, with
            ``ratios``, ``[dtheta, dr, dw, dv, dk]`` (n = 14).
        ratio_mean: mean log inertia ratios (2,) (the nominal inertia's), or None.
        ratios: whether the inertia ratios are uncertain (the state carries them).
    """

    rate_mean: ArrayF
    velocity_mean: ArrayF
    covariance: ArrayF
    ratio_mean: ArrayF | None
    ratios: bool

    @property
    def std(self) -> ArrayF:
        """Standard deviations (square roots of the covariance's diagonal)."""
        return np.sqrt(np.diag(self.covariance))


def magnitude_moments(scenario: Scenario) -> tuple[float, float]:
    """``(E[m], E[m^2])`` of the initial rate's magnitude, rad/s and rad^2/s^2."""
    if scenario.omega0_magnitude is None:
        m = math.sqrt(sum(v * v for v in scenario.omega0))
        return m, m * m
    a, b = scenario.omega0_magnitude
    if a == b:
        return a, a * a
    if scenario.omega0_magnitude_distribution == "log-uniform":
        log = math.log(b / a)
        return (b - a) / log, (b * b - a * a) / (2.0 * log)
    return (a + b) / 2.0, (a * a + a * b + b * b) / 3.0


def log_ratio_variance(spread: float) -> float:
    """``Var(ln(1 + e))`` for ``e ~ U(-spread, spread)``."""
    if spread == 0.0:
        return 0.0
    lo, hi = 1.0 - spread, 1.0 + spread

    def first(t: float) -> float:
        return t * math.log(t) - t

    def second(t: float) -> float:
        return t * math.log(t) ** 2 - 2.0 * t * math.log(t) + 2.0 * t

    mean = (first(hi) - first(lo)) / (2.0 * spread)
    return (second(hi) - second(lo)) / (2.0 * spread) - mean * mean


def error_prior(scenario: Scenario, *, ratios: bool | None = None) -> ErrorPrior:
    """The prior of ``scenario``'s initial state (module docstring). ``ratios``: carry the log
    inertia ratios (default: when the scenario's dynamics are free and its inertia uncertain,
    ``inertia_error > 0``); with ``ratios=True`` and a known inertia their variance is zero."""
    sc = scenario
    if ratios is None:
        ratios = sc.dynamics == "free" and sc.inertia_error > 0
    n = 14 if ratios else 12
    cov = np.zeros((n, n))
    if sc.attitude0 is None:
        cov[0:3, 0:3] = UNIFORM_ATTITUDE_VARIANCE * np.eye(3)
    cov[3:6, 3:6] = sc.position0_std**2 * np.eye(3)
    cov[9:12, 9:12] = sc.velocity0_std**2 * np.eye(3)
    mean_m, second_m = magnitude_moments(sc)
    omega0 = np.array(sc.omega0)
    axis = omega0 / np.linalg.norm(omega0) if omega0.any() else np.zeros(3)
    if sc.omega0_frame == "body" and sc.attitude0 is not None:
        axis = quat.rotation_matrix(np.array(sc.attitude0)) @ axis
    isotropic = sc.omega0_axis == "uniform" or (sc.omega0_frame == "body" and sc.attitude0 is None)
    if isotropic:  # uniform in direction: zero mean, E[m^2] / 3 per axis
        rate_mean = np.zeros(3)
        cov[6:9, 6:9] = second_m / 3.0 * np.eye(3)
    else:
        rate_mean = mean_m * axis
        cov[6:9, 6:9] = max(second_m - mean_m**2, 0.0) * np.outer(axis, axis)
    ratio_mean = None
    if ratios:
        from fkn_bench.models.rigid_body import inertia_ratios

        ratio_mean = np.array(inertia_ratios(sc.inertia))
        v = log_ratio_variance(sc.inertia_error) if sc.dynamics == "free" else 0.0
        cov[12:14, 12:14] = v * np.array([[2.0, -1.0], [-1.0, 2.0]])
    return ErrorPrior(rate_mean, np.array(sc.velocity0, dtype=float), cov, ratio_mean, bool(ratios))
