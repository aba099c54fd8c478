"""Built-in Kalman estimators: the paper's manual tuning on each filter variant, and the oracle.

* ``manual-ekf``: the additive EKF with the paper's manual tuning (FlexKalmanNet section 4.3):
  ``sigma_R = 0.1`` for all 7 measurement components, ``sigma_Q = 0.005`` for the quaternion and
  angular-rate components and ``1e-4`` for position and velocity.
* ``manual-ukf``: the same tuning on the UKF.
* ``manual-mekf``: the same tuning expressed for the multiplicative EKF's error state: a
  quaternion-component standard deviation ``s`` is an attitude standard deviation ``2 s`` (rad),
  so ``sigma_R = (0.2 rad x3, 0.1 m x3)`` and ``sigma_Q = (0.01 rad, 1e-4 m, 0.005 rad/s, 1e-4
  m/s)``.
* ``oracle-ekf``: the additive EKF with noise derived from the scenario's true noise
  (:mod:`fkn_bench.estimators.oracle`): the reference a tuned filter is measured against.

All initialise from the first measurement with ``P0`` standard deviations ``0.1`` (quaternion
components, m), ``0.2`` rad/s and ``0.003`` m/s (the MEKF: 0.2 rad attitude); see
:data:`fkn_bench.models.pose_twist.PAPER_MANUAL_LAYOUT` for the reasons.
"""

from __future__ import annotations

from typing import Any

from fkn_bench.estimators.kalman import KalmanEstimator
from fkn_bench.estimators.oracle import oracle_noise
from fkn_bench.estimators.registry import register_estimator
from fkn_bench.scenarios import ASTROBEE_INERTIA, Scenario

__all__ = ["manual_estimator", "oracle_ekf"]


def manual_estimator(variant: str) -> Any:
    """Factory of the manually tuned estimator on ``variant``."""

    def factory(scenario: Scenario | None = None, **options: Any) -> KalmanEstimator:
        options.setdefault("name", f"manual-{variant}")
        options.setdefault("description", f"{variant.upper()} with the paper's manual tuning")
        return KalmanEstimator(variant=variant, **options)

    return factory


def oracle_ekf(scenario: Scenario | None = None, **options: Any) -> KalmanEstimator:
    """The EKF with noise derived from ``scenario``'s true noise (a scenario is required)."""
    if scenario is None:
        raise ValueError("oracle-ekf needs the scenario whose true noise it uses")
    q_std, r_std = oracle_noise(scenario)
    options.setdefault("name", "oracle-ekf")
    options.setdefault("description", f"EKF with the true noise of {scenario.name}")
    return KalmanEstimator(variant="ekf", q_std=q_std, r_std=r_std, **options)


for _variant in ("ekf", "ukf", "mekf"):
    register_estimator(
        f"manual-{_variant}",
        manual_estimator(_variant),
        description=f"{_variant.upper()} with the paper's manual tuning (sigma_R 0.1; sigma_Q 0.005 q/w, 1e-4 r/v)",
    )
register_estimator("oracle-ekf", oracle_ekf, description="EKF with noise derived from the scenario's true noise")


def rigid_body_estimator(variant: str, *, ratios: bool) -> Any:
    """Factory of the torque-free rigid-body filter on ``variant`` with the paper's manual noise
    tuning: known inertia (the scenario's principal moments, else Astrobee's), or estimated
    inertia ratios (prior: isotropic)."""
    model = "rigid-body-ratios" if ratios else "rigid-body"

    def factory(scenario: Scenario | None = None, **options: Any) -> KalmanEstimator:
        if not ratios:
            options.setdefault("inertia", list(scenario.inertia if scenario is not None else ASTROBEE_INERTIA))
        options.setdefault("name", f"{model}-{variant}")
        options.setdefault("description", f"{variant.upper()} on the torque-free rigid body ({'inertia ratios estimated' if ratios else 'known inertia'})")
        return KalmanEstimator(variant=variant, model=model, **options)

    return factory


for _variant in ("ekf", "ukf", "mekf"):
    register_estimator(
        f"rigid-body-{_variant}",
        rigid_body_estimator(_variant, ratios=False),
        description=f"{_variant.upper()} on the torque-free rigid body with the scenario's inertia, paper's manual noise",
    )
    register_estimator(
        f"rigid-body-{_variant}-ratios",
        rigid_body_estimator(_variant, ratios=True),
        description=f"{_variant.upper()} on the torque-free rigid body, inertia ratios estimated online",
    )
