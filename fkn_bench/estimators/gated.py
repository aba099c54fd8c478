"""The ``-gated`` variants: registered Kalman estimators with a chi-square innovation gate.

A measurement whose normalised innovation squared ``nu^T S^-1 nu`` exceeds the
:data:`GATE_LEVEL` quantile of the chi-square distribution with as many degrees of freedom as the
innovation (6: attitude and position) is not used: the update is skipped and the step reports no
update (the validation gate: :meth:`fkn_bench.filters.KalmanFilter.set_gate`, after Bar-Shalom,
Li & Kirubarajan, *Estimation with Applications to Tracking and Navigation*, 2001). With the right ``S`` a 0.999 gate rejects one good
measurement in a thousand and every gross outlier (ds1-flips' random attitudes and 1 m position
errors), so that a 1% outlier rate does not read as a method failing. A gate is available to every
Kalman estimator as the option ``gate=LEVEL``; these variants are the registered entries that use
it, on the scenarios with gross outliers (``outlier_fraction > 0``; elsewhere they are not
available: on clean data the gate changes nothing, and where the noise is larger than the
filter's ``R`` it rejects good measurements, see the leaderboards' notes):

* ``manual-ekf-gated``: the paper's manual tuning;
* ``flexkalmannet-gated``: FlexKalmanNet's learned constant parameters;
* ``sage-husa-gated``, ``akhlaghi-gated``, ``vbakf-gated``: the tuned adaptive filters, gated
  before their rules see the measurement (an outlier neither moves the state nor feeds the noise
  estimates; :meth:`fkn_bench.baselines.adaptive.AdaptiveKalmanFilter.set_gate`).
"""

from __future__ import annotations

from typing import Any

from fkn_bench.estimators.base import Estimator
from fkn_bench.estimators.registry import EstimatorFactory, estimator_spec, register_estimator
from fkn_bench.scenarios import Scenario

__all__ = ["GATE_LEVEL", "GATED_ESTIMATORS", "gated_factory"]

GATE_LEVEL = 0.999
"""The variants' gate: the 0.999 quantile (22.46 for a 6-dimensional innovation)."""

GATED_ESTIMATORS: tuple[str, ...] = ("manual-ekf", "flexkalmannet", "sage-husa", "akhlaghi", "vbakf")
"""The estimators registered with a ``-gated`` variant."""


def gated_factory(base: str, level: float = GATE_LEVEL) -> EstimatorFactory:
    """Registry factory of ``<base>-gated``: ``base``'s factory with ``gate=level`` (an explicit
    ``gate`` option wins), named and described as the variant."""

    def factory(scenario: Scenario | None = None, **options: Any) -> Estimator:
        if scenario is not None and scenario.outlier_fraction == 0:
            raise ValueError(f"{base}-gated is for scenarios with gross outliers, and {scenario.name} has none "
                             f"(outlier_fraction 0); run {base}, or {base} with the option gate=LEVEL")
        options.setdefault("gate", level)
        estimator = estimator_spec(base).factory(scenario, **options)
        estimator.name = f"{base}-gated"
        estimator.description = f"{estimator.description}, chi-square innovation gate {options['gate']:g}"
        return estimator

    factory.__name__ = f"{base.replace('-', '_')}_gated_factory"
    return factory


for _base in GATED_ESTIMATORS:
    register_estimator(
        f"{_base}-gated",
        gated_factory(_base),
        description=f"{estimator_spec(_base).description}; chi-square innovation gate {GATE_LEVEL:g}",
    )
